"""
The rig's process table: which nodes run, with what parameters, started and stopped in order.

One table for the simulated rig (``sim_table``: sim_node, then coils_node, inserter_node,
backbone_node where the scene has a backbone, tracker_node, each on config/sim/*.yaml) and
the real one (``real_table``: the same drivers on a lab's params files). ``Rig`` starts each
entry as its own process, as deployed (``python -m``, its own session: a Ctrl-C at the
terminal reaches the bringup only, which stops the rest in order), starts each once the one
before says it runs (so the simulator's devices are linked before the drivers open them),
and stops the drivers first (the supplies at zero and off, the axes stopped, each confirmed
by the driver's last line), then the watchers, then the simulator. scripts/rig runs it; the
tests and benches start the rig with it too, so the table they test is the one a lab runs.
"""

from dataclasses import dataclass, replace
import os
import pathlib
import signal
import sys
import time

from tentacle_common.contract import axis_node_name
from tentacle_sim.sim_rig import NodeProcess

# What stops first: the player (it stops commanding), the drivers (each confirming its safe
# state), the watchers, the recorder (it has recorded the stop), the simulator.
STOP_ORDER = ('commander', 'driver', 'watcher', 'recorder', 'sim')
CONFIRMED = {'coils_node': 'outputs zero and off', 'inserter_node': 'axis stopped',
             'backbone_node': 'axis stopped',   # the line a driver ends with when safe
             'recorder_node': 'recording closed'}   # ... and the recorder with its bag whole
DRIVER_STOP_S = 40.0   # a ramp to zero at the slowest slew, and its read-back
# Fast DDS with a 64 MB shared-memory segment: camera frames (3 MB) between processes in a
# third of the time of the default transports (bench/README.md, vision_speed.py).
TRANSPORT_PROFILE = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'config/fastdds_large_images.xml')


@dataclass(frozen=True)
class Entry:
    """One process of the table."""

    name: str                 # the node name (its log file, its line at exit)
    module: str               # run as python -m module
    args: tuple = ()          # after the module: --ros-args ...
    role: str = 'driver'      # 'commander', 'driver' (confirmed), 'watcher', 'recorder', 'sim'
    env: tuple = ()           # (name, value) pairs set for the process (unless already set)


def _ros_args(params_file, node_name=None, **overrides):
    args = ['--ros-args', *(('-r', f'__node:={node_name}') if node_name else ()),
            '--params-file', str(params_file)]
    return tuple(args) + _parameter_args(overrides)


def scene_has_backbone(scene_file):
    """Return whether a scene's tentacle has a backbone (a backbone stage to run)."""
    from tentacle_planner.scene import load_scene
    return load_scene(scene_file).tentacle.backbone is not None


def sim_table(scene_file, root, device_dir=None, tracker=True, schedule=None, player=None,
              record=None, **sim_params):
    """
    Return the simulated rig's entries: sim_node and the drivers on config/sim/*.yaml.

    :param scene_file: the scene sim_node simulates
    :param root: the project root (config/sim lives there)
    :param device_dir: sim_node's device folder (default config/sim's, /tmp/tentacle_sim);
        the drivers' ports follow it
    :param tracker: run tracker_node on the simulated camera
    :param schedule: a schedule file: sim_node's tentacle is the one made to its plan, and
        player_node runs to play it
    :param player: more player_node parameters (e.g. {'mode': 'closed_loop'})
    :param record: a bag directory: recorder_node records the run into it
    :param sim_params: more sim_node parameters (e.g. camera_rate)
    """
    sim_dir = pathlib.Path(root) / 'config' / 'sim'
    if schedule is not None:
        sim_params['schedule'] = str(schedule)
    ports = {}
    if device_dir is not None:
        sim_params['device_dir'] = str(device_dir)
        ports = {'coils': {'ports': '[' + ','.join(f'{device_dir}/coil_{a}' for a in 'xyz')
                           + ']'},
                 'inserter': {'port': f'{device_dir}/inserter'},
                 'backbone': {'port': f'{device_dir}/backbone'},
                 'tracker': {'background_image': f'{device_dir}/background.png'}}
    table = [Entry('sim_node', 'tentacle_sim.sim_node',
                   _ros_args(sim_dir / 'sim.yaml', scene=scene_file, **sim_params), 'sim'),
             Entry('coils_node', 'tentacle_coils.coils_node',
                   _ros_args(sim_dir / 'coils.yaml', **ports.get('coils', {}))),
             Entry('inserter_node', 'tentacle_inserter.inserter_node',
                   _ros_args(sim_dir / 'inserter.yaml', **ports.get('inserter', {})))]
    if scene_has_backbone(scene_file):
        table.append(Entry('backbone_node', 'tentacle_inserter.inserter_node',
                           _ros_args(sim_dir / 'backbone.yaml', axis_node_name('backbone'),
                                     **ports.get('backbone', {}))))
    if tracker:
        table.append(Entry('tracker_node', 'tentacle_vision.tracker_node',
                           _ros_args(sim_dir / 'tracker.yaml', **_camera_of(sim_params),
                                     **ports.get('tracker', {})),
                           'watcher'))
    return with_transport(table + run_entries(root, sim_dir / 'player.yaml', schedule, player,
                                              record), root)


def run_entries(root, player_params, schedule=None, player=None, record=None):
    """
    Return the entries that play and record a run: recorder_node, then player_node.

    :param player_params: player_node's params file (it runs when a schedule is given)
    """
    entries = []
    if record is not None:
        entries.append(Entry('recorder_node', 'tentacle_rig.recorder_node',
                             _ros_args(pathlib.Path(root) / 'config' / 'recorder.yaml',
                                       out=record), 'recorder'))
    if schedule is not None:
        entries.append(Entry('player_node', 'tentacle_planner.player_node',
                             _ros_args(player_params, schedule=schedule, **(player or {})),
                             'commander'))
    return entries


def _camera_of(sim_params):
    """Return the tracker's overrides matching sim_node's camera overrides."""
    return {k: sim_params[k] for k in ('base_px', 'metres_per_px') if k in sim_params}


def real_table(config_dir, root=None, schedule=None, player=None, record=None):
    """
    Return the real rig's entries: each driver whose params file is in config_dir.

    coils.yaml (coils_node), inserter.yaml (inserter_node), backbone.yaml (backbone_node),
    camera.yaml (camera_node), tracker.yaml (tracker_node); with a schedule, player_node on
    player.yaml (the lab's: its limits and its tentacle file); with ``record``, recorder_node
    on the project's config/recorder.yaml (``root``). With ``root``, every process runs on
    its Fast DDS profile for camera frames (``with_transport``).

    :raises FileNotFoundError: the folder has none of the drivers' files, or a schedule is
        given without player.yaml
    """
    folder = pathlib.Path(config_dir)
    rows = [('coils.yaml', 'coils_node', 'tentacle_coils.coils_node', None, 'driver'),
            ('inserter.yaml', 'inserter_node', 'tentacle_inserter.inserter_node', None,
             'driver'),
            ('backbone.yaml', 'backbone_node', 'tentacle_inserter.inserter_node',
             axis_node_name('backbone'), 'driver'),
            ('camera.yaml', 'camera_node', 'tentacle_vision.camera_node', None, 'watcher'),
            ('tracker.yaml', 'tracker_node', 'tentacle_vision.tracker_node', None, 'watcher')]
    table = [Entry(name, module, _ros_args(folder / file, node_name), role)
             for file, name, module, node_name, role in rows if (folder / file).is_file()]
    if not table:
        raise FileNotFoundError(f'{folder}: none of coils.yaml, inserter.yaml, backbone.yaml, '
                                'camera.yaml, tracker.yaml')
    if schedule is not None and not (folder / 'player.yaml').is_file():
        raise FileNotFoundError(f'{folder}: no player.yaml to play a schedule with (copy '
                                'config/sim/player.yaml and set the tentacle file and limits '
                                'of this rig)')
    table += run_entries(root, folder / 'player.yaml', schedule, player, record)
    return table if root is None else with_transport(table, root)


def with_overrides(table, overrides):
    """Return the table with more parameters for some nodes: {node name: {name: value}}."""
    return [replace(entry, args=entry.args + _parameter_args(overrides.get(entry.name, {})))
            for entry in table]


def _parameter_args(values):
    return tuple(arg for name, value in values.items() for arg in ('-p', f'{name}:={value}'))


def with_transport(table, root):
    """Return the table with every process on the project's Fast DDS profile (under root)."""
    name, relative = TRANSPORT_PROFILE
    return [replace(entry, env=((name, str(pathlib.Path(root) / relative)),))
            for entry in table]


class RigError(RuntimeError):
    """A process of the table did not come up."""


class Rig:
    """The processes of a table, started in order, stopped drivers first."""

    def __init__(self, table, log_dir, cwd=None, say=print, ready_timeout_s=90.0,
                 cancelled=lambda: False):
        """
        Start every entry in turn, each once the one before runs.

        So the simulator's devices are linked before a driver opens them.

        :param log_dir: each process's output goes to log_dir/<name>.log
        :param say: where progress lines go (a callable taking one line)
        :param cancelled: polled while waiting: True stops what has started and raises
        :raises RigError: a process died, did not say it runs in ready_timeout_s, or the
            start was cancelled (every process started so far is stopped again)
        """
        self.log_dir = pathlib.Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.say, self.processes = say, []
        try:
            for entry in table:
                process = NodeProcess([sys.executable, '-m', entry.module, *entry.args],
                                      str(self.log_dir / f'{entry.name}.log'), cwd,
                                      {**dict(entry.env), **os.environ})
                self.processes.append((entry, process))
                say(f'rig: started {entry.name} (pid {process.popen.pid})')
                self._wait_running(entry, process, ready_timeout_s, cancelled)
        except BaseException:
            self.stop()
            raise

    @staticmethod
    def _wait_running(entry, process, timeout_s, cancelled):
        deadline = time.monotonic() + timeout_s
        while True:
            if f'{entry.name}: running' in process.output():
                return
            if process.popen.poll() is not None:
                raise RigError(f'{entry.name} exited ({process.popen.returncode}):\n'
                               + process.output()[-2000:])
            if cancelled():
                raise RigError(f'cancelled while {entry.name} was starting')
            if time.monotonic() > deadline:  # the output was read once more above
                raise RigError(f'{entry.name} did not say it runs in {timeout_s:g} s:\n'
                               + process.output()[-2000:])
            time.sleep(0.05)

    def process(self, name):
        """Return the NodeProcess of a name."""
        return next(p for e, p in self.processes if e.name == name)

    def alive(self):
        """Return the names of the processes still running."""
        return [e.name for e, p in self.processes if p.popen.poll() is None]

    def stop(self, sig=signal.SIGINT):
        """
        Stop the drivers (each confirming its safe state), the watchers, then the simulator.

        :return: [(name, exit code, its last line, confirmed safe)] in stopping order
        """
        report = []
        for role in STOP_ORDER:
            for entry, process in reversed([(e, p) for e, p in self.processes
                                            if e.role == role]):
                code = process.stop(sig, DRIVER_STOP_S if role == 'driver' else 10.0)
                lines = [line for line in process.output().splitlines()
                         if line.startswith(f'{entry.name}: ')]
                last = lines[-1] if lines else '(no last line)'
                safe = entry.name not in CONFIRMED or (CONFIRMED[entry.name] in last
                                                       and code == 0)
                report.append((entry.name, code, last, safe))
                self.say(f'rig: {entry.name} stopped (exit {code}): {last}'
                         + ('' if safe else '  <-- NOT CONFIRMED SAFE'))
        self.processes = []
        return report
