"""
Style and structure checks, as a ROS package's generated lint tests would run them.

flake8 and pep257 with the ament configuration (line length 99), and the rule that pure
logic never imports rclpy: only ``*_node.py`` modules (and test/bench/lab-script glue) may.
"""

import ast

from ament_flake8.main import main_with_errors as flake8_main
from ament_pep257.main import main as pep257_main
import pytest
from rig_support import ROOT

PYTHON_TREES = ['src', 'tests', 'bench', 'scripts', 'config', 'conftest.py']
ROS_MODULES = ('rclpy', 'geometry_msgs', 'std_msgs', 'std_srvs', 'diagnostic_msgs',
               'sensor_msgs', 'nav_msgs', 'rcl_interfaces')


def python_files():
    files = [p for tree in PYTHON_TREES for p in (
        [ROOT / tree] if tree.endswith('.py') else (ROOT / tree).rglob('*.py'))]
    return files + [ROOT / 'scripts' / 'ros2_run']


def test_flake8():
    rc, errors = flake8_main(argv=[str(p) for p in python_files()])
    assert rc == 0, f'{len(errors)} flake8 errors:\n' + '\n'.join(errors)


def test_pep257():
    assert pep257_main(argv=[str(ROOT / t) for t in PYTHON_TREES]) == 0


def package_modules():
    for package in sorted((ROOT / 'src').iterdir()):
        source = package / package.name
        if source.is_dir():
            yield from sorted(source.glob('*.py'))


@pytest.mark.parametrize('module', list(package_modules()), ids=lambda p: p.name)
def test_only_node_modules_import_ros(module):
    tree = ast.parse(module.read_text())
    imported = {alias.name.split('.')[0] for node in ast.walk(tree)
                if isinstance(node, ast.Import) for alias in node.names}
    imported |= {node.module.split('.')[0] for node in ast.walk(tree)
                 if isinstance(node, ast.ImportFrom) and node.module}
    ros = imported & set(ROS_MODULES)
    if module.name.endswith('_node.py'):
        return
    assert not ros, f'{module.relative_to(ROOT)} is pure logic but imports {sorted(ros)}'


def test_test_modules_have_unique_names():
    # The test folders are not packages: pytest imports each test module by its basename, so
    # two of one name fail the whole collection (make test stops before the first test).
    seen = {}
    for path in sorted([*ROOT.glob('src/*/test/test_*.py'), *ROOT.glob('tests/**/test_*.py')]):
        seen.setdefault(path.name, []).append(str(path.relative_to(ROOT)))
    assert {name: paths for name, paths in seen.items() if len(paths) > 1} == {}


def test_topic_names_are_written_once_in_the_contract():
    # STYLE.md 12: a topic's name (/coils/field_cmd, say) is written once; the rest import it.
    from tentacle_common import contract
    names = {v.name for v in vars(contract).values()
             if isinstance(v, (contract.Topic, contract.Service))}
    names |= {f(axis).name for axis in contract.AXES
              for f in (contract.axis_target, contract.axis_state)}
    names |= {contract.axis_service(axis, verb).name for axis in contract.AXES
              for verb in ('stop', 'home', 'enable')}
    names |= {contract.player_service(verb).name for verb in contract.PLAYER_VERBS}
    quoted = [(q + name + q) for name in names for q in '\'"']
    found = [f'{path.relative_to(ROOT)}: {text}' for path in python_files()
             if path.name not in ('contract.py', 'test_contract.py')
             for text in quoted if text in path.read_text()]
    assert not found, 'topic names written out instead of taken from contract:\n' + '\n'.join(
        found)
