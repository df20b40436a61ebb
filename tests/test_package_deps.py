"""
Every package declares in package.xml what its code and its tests import.

Each package's .py files are walked with ast (functions' imports too): a third-party or
sibling import in the package's code needs an exec_depend (or depend) on its rosdep key, one
in its test/ folder a test_depend (or an exec_depend). IMPORT_KEYS maps import names to
rosdep keys: a new third-party import fails here until it has a row, and then until the
package declares it. Standard-library modules need nothing.
"""

import ast
import sys
import xml.etree.ElementTree as ElementTree

import pytest
from rig_support import ROOT

IMPORT_KEYS = {  # import name -> rosdep key
    'cv2': 'python3-opencv',
    'dask': 'python3-dask',
    'distributed': 'python3-distributed',
    'hypothesis': 'python3-hypothesis',
    'matplotlib': 'python3-matplotlib',
    'numba': 'python3-numba',
    'numpy': 'python3-numpy',
    'pyarrow': 'python3-pyarrow',
    'pytest': 'python3-pytest',
    'scipy': 'python3-scipy',
    'serial': 'python3-serial',
    'sklearn': 'python3-sklearn',
    'threadpoolctl': 'python3-threadpoolctl',
    'rosbags': 'python3-rosbags',
    'tqdm': 'python3-tqdm',
    'yaml': 'python3-yaml',
    **{ros: ros for ros in ('rclpy', 'rcl_interfaces', 'std_msgs', 'std_srvs',
                            'geometry_msgs', 'sensor_msgs', 'nav_msgs', 'diagnostic_msgs',
                            'visualization_msgs', 'ament_index_python', 'launch',
                            'launch_ros')},
}
PACKAGES = sorted(p for p in (ROOT / 'src').iterdir() if (p / 'package.xml').exists())


def declared(package):
    """Return (exec keys, test keys) of a package.xml; depend counts for both."""
    root = ElementTree.parse(package / 'package.xml').getroot()
    keys = {tag: {e.text.strip() for e in root.iter(tag)}
            for tag in ('depend', 'exec_depend', 'test_depend')}
    run = keys['depend'] | keys['exec_depend']
    return run, run | keys['test_depend']


def imports(path):
    """Return {top-level name: first line} of the absolute imports in a Python file."""
    found = {}
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        for name in names:
            found.setdefault(name.split('.')[0], node.lineno)
    return found


def needed(package):
    """Return [(rosdep key, 'exec' or 'test', where)] the package's files import."""
    siblings = {p.name for p in PACKAGES}
    needs = []
    for path in sorted(package.rglob('*.py')):
        relative = path.relative_to(package)
        if relative.parts[0] in ('build', 'install', 'log') or relative.name == 'setup.py':
            continue  # setup.py's setuptools is colcon's own, not the package's
        kind = 'test' if relative.parts[0] == 'test' else 'exec'
        for name, line in imports(path).items():
            if name in sys.stdlib_module_names or name == package.name:
                continue
            if name in siblings:
                key = name
            elif name in IMPORT_KEYS:
                key = IMPORT_KEYS[name]
            else:
                key = f'<no rosdep key for {name!r}: add a row to IMPORT_KEYS>'
            needs.append((key, kind, f'{relative}:{line}'))
    return needs


@pytest.mark.parametrize('package', PACKAGES, ids=lambda p: p.name)
def test_every_import_is_declared(package):
    run, test = declared(package)
    missing = sorted({(key, kind, where) for key, kind, where in needed(package)
                      if key not in (run if kind == 'exec' else test)},
                     key=lambda m: (m[1], m[0]))
    first = {}
    for key, kind, where in missing:
        first.setdefault((key, kind), where)
    assert not first, f'{package.name}/package.xml lacks:\n' + '\n'.join(
        f'  <{kind}_depend>{key}</{kind}_depend>  (imported at {where})'
        for (key, kind), where in first.items())


def test_an_undeclared_import_is_found(tmp_path):
    package = tmp_path / 'demo_pkg'
    (package / 'demo_pkg').mkdir(parents=True)
    (package / 'test').mkdir()
    (package / 'package.xml').write_text(
        '<package format="3"><name>demo_pkg</name><exec_depend>python3-numpy</exec_depend>'
        '<test_depend>python3-pytest</test_depend></package>')
    (package / 'demo_pkg' / 'tool.py').write_text(
        'import json\nimport numpy as np\n\n\ndef f():\n    import yaml\n    return yaml\n')
    (package / 'test' / 'test_tool.py').write_text('import pytest\nimport cv2\n')
    run, test = declared(package)
    missing = sorted((key, kind, where) for key, kind, where in needed(package)
                     if key not in (run if kind == 'exec' else test))
    assert missing == [('python3-opencv', 'test', 'test/test_tool.py:2'),
                       ('python3-yaml', 'exec', 'demo_pkg/tool.py:6')]
