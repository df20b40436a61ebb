"""The launch file starts what scripts/rig starts: its nodes are the process table's rows."""

import importlib.util
import pathlib
import re
import sys
import types

import pytest
from tentacle_rig.bringup import Entry, real_table, sim_table
from tentacle_rig.launch_rows import launch_row, launch_rows

ROOT = pathlib.Path(__file__).resolve().parents[3]
LAUNCH_FILE = ROOT / 'src' / 'tentacle_rig' / 'launch' / 'rig.launch.py'
SCENE = ROOT / 'config' / 'scenes' / 'pancreatic_duct.yaml'


def console_scripts(package):
    """Return the executables a package's setup.py installs, by name."""
    text = (ROOT / 'src' / package / 'setup.py').read_text()
    return dict(re.findall(r"'([\w-]+) = ([\w.]+):main'", text))


@pytest.mark.parametrize('table', [
    sim_table(SCENE, ROOT, '/tmp/devices', schedule='out/schedule.yaml', record='out/bag'),
    sim_table(ROOT / 'config/scenes/ch6_coiling.yaml', ROOT)], ids=['duct', 'ch6'])
def test_every_row_is_an_installed_executable_with_the_tables_ros_arguments(table):
    for entry, row in zip(table, launch_rows(table)):
        scripts = console_scripts(row['package'])
        assert scripts.get(row['executable']) == entry.module   # what scripts/rig runs
        assert ['--ros-args', *row['ros_arguments']] == list(entry.args)


def test_every_process_runs_on_the_projects_shared_memory_profile_for_frames(tmp_path):
    profile = str(ROOT / 'config' / 'fastdds_large_images.xml')
    lab = tmp_path / 'lab'
    lab.mkdir()
    (lab / 'camera.yaml').write_text('{}\n')
    for table in (sim_table(SCENE, ROOT), real_table(lab, ROOT)):
        assert all(row['additional_env'] == {'FASTRTPS_DEFAULT_PROFILES_FILE': profile}
                   for row in launch_rows(table))
    assert pathlib.Path(profile).is_file()
    assert 'additional_env' not in launch_rows(real_table(lab))[0]   # no project: no profile


def test_a_row_that_cannot_be_launched_is_refused():
    with pytest.raises(ValueError, match='not package.executable'):
        launch_row(Entry('x', 'tentacle_rig', ('--ros-args',)))
    with pytest.raises(ValueError, match='arguments before --ros-args'):
        launch_row(Entry('x', 'tentacle_rig.recorder_node', ('-p',)))


class FakeLaunch:
    """Stand-ins for launch and launch_ros (not installable here): they record the calls."""

    def __init__(self, values):
        self.values = values
        self.modules = {name: types.ModuleType(name) for name in (
            'launch', 'launch.actions', 'launch.substitutions', 'launch_ros',
            'launch_ros.actions')}
        m = self.modules
        m['launch'].LaunchDescription = lambda actions: actions
        m['launch.actions'].DeclareLaunchArgument = lambda name, **kw: ('argument', name)
        m['launch.actions'].OpaqueFunction = lambda function: ('opaque', function)
        outer = self

        class Configuration:
            def __init__(self, name):
                self.name = name

            def perform(self, context):
                return outer.values.get(self.name, '')
        m['launch.substitutions'].LaunchConfiguration = Configuration
        m['launch_ros.actions'].Node = lambda **kw: kw

    def run(self):
        """Load the launch file with the stand-ins; return the Node keyword sets it makes."""
        saved = {name: sys.modules.get(name) for name in self.modules}
        sys.modules.update(self.modules)
        try:
            spec = importlib.util.spec_from_file_location('rig_launch', LAUNCH_FILE)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            actions = module.generate_launch_description()
            opaque = [a[1] for a in actions if a[0] == 'opaque']
            return opaque[0](context=None)
        finally:
            for name, previous in saved.items():
                if previous is None:
                    sys.modules.pop(name, None)
                else:
                    sys.modules[name] = previous


def test_the_launch_file_starts_the_tables_nodes(tmp_path):
    lab = tmp_path / 'lab'
    lab.mkdir()
    for name in ('coils.yaml', 'inserter.yaml', 'tracker.yaml', 'player.yaml'):
        (lab / name).write_text('{}\n')
    cases = [({'scene': str(SCENE), 'root': str(ROOT), 'schedule': 's.yaml', 'record': 'bag'},
              sim_table(SCENE, ROOT, None, True, 's.yaml', None, 'bag')),
             ({'config': str(lab), 'root': str(ROOT), 'schedule': 's.yaml'},
              real_table(lab, ROOT, 's.yaml'))]
    for values, table in cases:
        nodes = FakeLaunch(values).run()
        assert nodes == [dict(row, output='screen') for row in launch_rows(table)]
        assert [n['executable'] for n in nodes][-1] == 'player_node'
    with pytest.raises(RuntimeError, match='one of them'):
        FakeLaunch({'root': str(ROOT)}).run()
