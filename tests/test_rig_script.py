"""
scripts/rig as a lab runs it: up from the process table, down with Ctrl-C in order.

The simulated rig (the validation cantilever), the real table on emulated devices, a second
Ctrl-C during the stop, and a node that dies on its own.
"""

import os
import pathlib
import signal
import subprocess
import threading
import time

from plans import short_duct
import pytest
from rig_support import ROOT, wait_for
from tentacle_common import contract
from tentacle_rig.recording import read_bag
from tentacle_sim.emulator_client import EmulatorProcess, StageEmulatorProcess
from tentacle_sim.sim_devices import ask
import yaml

pytestmark = pytest.mark.ros


class Script:
    """A script of scripts/ in a process of its own, its output collected line by line."""

    def __init__(self, name, *args):
        self.popen = subprocess.Popen([str(ROOT / 'scripts' / name), *map(str, args)],
                                      stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                      text=True, start_new_session=True)
        self.lines = []
        threading.Thread(target=lambda: self.lines.extend(self.popen.stdout),
                         daemon=True).start()

    def text(self):
        return ''.join(self.lines)

    def up(self):
        return wait_for(lambda: 'rig: up' in self.text() or self.popen.poll() is not None,
                        90.0) and 'rig: up' in self.text()

    def pid(self, name):
        line = next(x for x in self.lines if x.startswith(f'rig: started {name} '))
        return int(line.split('pid ')[1].rstrip(')\n'))

    def wait(self, timeout_s=120.0):
        try:
            return self.popen.wait(timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(self.popen.pid, signal.SIGKILL)
            raise

    def stopped_order(self):
        return [x.split()[1] for x in self.lines if ' stopped (exit ' in x]

    def close(self):
        """Stop it if a failed test left it running: Ctrl-C (the rig stops in order)."""
        if self.popen.poll() is None:
            os.killpg(self.popen.pid, signal.SIGINT)
            try:
                self.popen.wait(90.0)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait()


@pytest.fixture
def script():
    """Return a factory of Scripts; any still running at the end is stopped (a rig too)."""
    started = []

    def start(name, *args):
        started.append(Script(name, *args))
        return started[-1]
    yield start
    for handle in reversed(started):
        handle.close()


def cantilever_scene(folder):
    path = folder / 'scene.yaml'
    path.write_text(yaml.safe_dump({
        'tentacle': str(ROOT / 'config/tentacles/cantilever.yaml'),
        'path': {'points_m': [[0.0, 0.0, 0.0], [0.02, 0.0, 0.0]]},
        'insertion_steps_m': [0.02], 'model': {'dof': 1, 'sublinks': 8}}))
    return path


def test_sim_up_a_recorded_run_then_down_player_and_drivers_first(tmp_path, script):
    scene, schedule = short_duct(tmp_path, (3,))
    rig = script('rig', '--sim', scene, '--schedule', schedule, '--record', tmp_path / 'bags',
                 '--device-dir', tmp_path / 'dev', '--logs', tmp_path / 'logs')
    assert rig.up(), rig.text()
    assert 'DDS discovery LOCALHOST' in rig.text()
    # Camera frames between processes over a large shared-memory segment (the table's env).
    environ = pathlib.Path(f'/proc/{rig.pid("sim_node")}/environ').read_bytes().split(b'\0')
    assert f'FASTRTPS_DEFAULT_PROFILES_FILE={ROOT}/config/fastdds_large_images.xml'.encode() \
        in environ
    # Driven from another terminal, as a lab user would: the devices say it happened.
    for args in (('home',), ('background',), ('play', '--mode', 'closed_loop')):
        done = command(*args)
        assert done.returncode == 0, done.stdout + done.stderr
    assert 'step 3/3' in done.stdout and 'the run: done' in done.stdout
    assert ask(tmp_path / 'dev', {'op': 'state'})['inserter']['position_m'] == pytest.approx(
        0.003, abs=2e-5)
    # Aborted, the player lets go of the coils once their zero reads back: a lab may drive.
    assert command('abort').returncode == 0
    moved = command('insert', '0.005')
    assert moved.returncode == 0, moved.stdout + moved.stderr
    assert ask(tmp_path / 'dev', {'op': 'state'})['inserter']['position_m'] == pytest.approx(
        0.005, abs=1e-5)
    holding = script('rig-command', 'field', '0', '0.005', '0')
    assert wait_for(lambda: ask(tmp_path / 'dev', {'op': 'state'})['coil_y'][
        'current_a'] == pytest.approx(0.005 / 1.07e-3, abs=0.02), 20.0), holding.text()
    time.sleep(1.5)   # past coils_node's 1 s watchdog: still held
    assert ask(tmp_path / 'dev', {'op': 'state'})['coil_y']['current_a'] == pytest.approx(
        0.005 / 1.07e-3, abs=0.02)
    holding.popen.send_signal(signal.SIGINT)
    assert holding.wait(20) == 0
    assert wait_for(lambda: 'stopped holding' in holding.text(), 5.0), holding.text()
    # Watching: the simulator's truth reaches it once discovery has matched them (seconds
    # on a loaded machine).
    watching = script('rig-command', 'watch', '--rate', '5')
    assert wait_for(lambda: 'tip (truth) [' in watching.text(), 60.0), watching.text()
    watching.popen.send_signal(signal.SIGINT)
    assert watching.wait(20) == 0
    assert wait_for(lambda: 'stopped watching' in watching.text(), 5.0), watching.text()
    assert 'Traceback' not in watching.text()
    os.killpg(rig.popen.pid, signal.SIGINT)
    assert wait_for(lambda: 'rig: coils_node stopped' in rig.text()
                    or 'rig: inserter_node stopped' in rig.text()
                    or rig.popen.poll() is not None, 60.0)
    os.killpg(rig.popen.pid, signal.SIGINT)   # the second Ctrl-C: the stop goes on
    assert rig.wait() == 0, rig.text()
    order = rig.stopped_order()
    assert order[0] == 'player_node' and set(order[1:3]) == {'coils_node', 'inserter_node'}
    assert order[3:] == ['tracker_node', 'recorder_node', 'sim_node'], rig.text()
    assert 'coils_node: outputs zero and off' in rig.text()
    assert 'inserter_node: axis stopped' in rig.text()
    assert not (tmp_path / 'dev' / 'coil_x').exists()   # the simulator went last, links too
    # The recording was closed whole: rosbag2's metadata, every step, the supplies' last word.
    bag = read_bag(next((tmp_path / 'bags').iterdir()))
    steps = [int(m.position[0]) for _, m in bag[contract.PLAYER_PROGRESS.name]]
    assert steps[0] == 1 and 3 in steps
    currents = bag[contract.CURRENTS.name][-1][1].vector
    assert max(abs(currents.x), abs(currents.y), abs(currents.z)) < 1e-3   # zero, first


def test_a_node_that_dies_stops_the_rig_safely_and_says_so(tmp_path, script):
    rig = script('rig', '--sim', cantilever_scene(tmp_path), '--device-dir', tmp_path / 'dev',
                 '--logs', tmp_path / 'logs', '--no-tracker')
    assert rig.up(), rig.text()
    os.kill(rig.pid('inserter_node'), signal.SIGKILL)
    assert rig.wait() == 1, rig.text()
    assert 'inserter_node exited on its own' in rig.text()
    assert 'coils_node: outputs zero and off' in rig.text()
    assert 'NOT confirmed safe: inserter_node' in rig.text()   # it could not say


def test_real_table_on_a_labs_params_files(tmp_path, script):
    supplies = EmulatorProcess(tmp_path / 'ports', 'scpi', 115200)
    stages = StageEmulatorProcess(tmp_path / 'ports')
    try:
        config = tmp_path / 'lab'
        config.mkdir()
        coils = yaml.safe_load((ROOT / 'config/sim/coils.yaml').read_text())
        coils['coils_node']['ros__parameters'].update(
            ports=[supplies.ports[a] for a in 'xyz'], dialect='scpi', baud=115200)
        (config / 'coils.yaml').write_text(yaml.safe_dump(coils))
        inserter = yaml.safe_load((ROOT / 'config/sim/inserter.yaml').read_text())
        inserter['inserter_node']['ros__parameters']['port'] = stages.ports['inserter']
        (config / 'inserter.yaml').write_text(yaml.safe_dump(inserter))
        rig = script('rig', '--real', config, '--logs', tmp_path / 'logs')
        assert rig.up(), rig.text()
        assert wait_for(lambda: all(s['output_on'] for s in supplies.state().values()), 30.0)
        os.killpg(rig.popen.pid, signal.SIGTERM)
        assert rig.wait() == 0, rig.text()
        # Read back from the devices, not taken from the driver's word.
        assert all(not s['output_on'] and s['setpoint_a'] == 0.0
                   for s in supplies.state().values())
    finally:
        supplies.stop()
        stages.stop()


def command(*args):
    return subprocess.run([str(ROOT / 'scripts' / 'rig-command'), '--wait-s', '5', *args],
                          capture_output=True, text=True, timeout=120)


def test_a_command_without_a_rig_says_so_and_a_bad_one_is_a_usage_error():
    nobody = command('--wait-s', '0.5', 'estop', 'on')
    assert nobody.returncode == 1 and 'is the rig up?' in nobody.stderr
    assert command('field', '0', 'x', '0').returncode == 2
    assert command('--axis', 'in-serter', 'home').returncode == 2


def test_usage_errors_exit_2(tmp_path, script):
    for args in (['--sim', tmp_path / 'absent.yaml'], ['--real', tmp_path],
                 ['--real', tmp_path, '--no-tracker'], []):
        assert script('rig', *args).wait(30.0) == 2
