"""Cross-process test rig: emulated supplies and the coils node as real processes over DDS.

Every run claims a private ROS_DOMAIN_ID (a lock file per domain, so parallel runs on one
machine never share one) with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, before rclpy is
imported. Every process a test starts is stopped when the test ends.
"""

import fcntl
import json
import os
import pathlib
import signal
import subprocess
import sys
import threading
import time

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOMAIN_RANGE = range(100, 200)


def _claim_domain():
    for domain in [100 + (os.getpid() + k) % 100 for k in range(len(DOMAIN_RANGE))]:
        handle = open(f'/tmp/tentacle_rig_ros_domain_{domain}.lock', 'w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return domain, handle
        except OSError:
            handle.close()
    raise RuntimeError('no free ROS_DOMAIN_ID in 100..199')


DOMAIN_ID, _DOMAIN_LOCK = _claim_domain()
os.environ['ROS_DOMAIN_ID'] = str(DOMAIN_ID)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['PYTHONPATH'] = os.pathsep.join(
    [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]
    + [os.environ.get('PYTHONPATH', '')]).rstrip(os.pathsep)
os.environ['PYTHONUNBUFFERED'] = '1'


def wait_for(predicate, timeout_s=5.0, period_s=0.01):
    """Return True as soon as predicate() is true, False after timeout_s."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period_s)
    return False


class Process:
    """A child process with its output collected in a file."""

    def __init__(self, argv, log_path, stdin=None):
        """Start argv; stdout and stderr go to log_path."""
        self.log_path = log_path
        self._log = open(log_path, 'w')
        self.popen = subprocess.Popen(argv, stdin=stdin, stdout=self._log,
                                      stderr=subprocess.STDOUT, cwd=ROOT,
                                      start_new_session=True)

    def output(self):
        """Return everything the process printed so far."""
        return pathlib.Path(self.log_path).read_text()

    def stop(self, sig=signal.SIGINT, timeout_s=10.0):
        """Signal the process, wait for it; kill it if it hangs. Return its exit code."""
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait()
        self._log.close()
        return self.popen.returncode


class Emulators:
    """The supply_emulator process, driven over its stdin/stdout JSON lines."""

    def __init__(self, tmp_path, dialect='dxkdp', baud=9600, extra=()):
        """Start three emulated supplies with stable port links under tmp_path."""
        argv = [sys.executable, '-m', 'tentacle_sim.emulate_supplies', '--dialect', dialect,
                '--baud', str(baud), '--link-dir', str(tmp_path / 'ports'), *extra]
        self.popen = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      text=True, cwd=ROOT, start_new_session=True)
        self._lock = threading.Lock()
        ready = json.loads(self.popen.stdout.readline())
        self.ports = ready['ports']

    def ask(self, **request):
        """Send one control request; return the reply."""
        with self._lock:
            self.popen.stdin.write(json.dumps(request) + '\n')
            self.popen.stdin.flush()
            return json.loads(self.popen.stdout.readline())

    def state(self):
        """Return every supply's state."""
        return self.ask(op='state')

    def setpoints(self):
        """Return the setpoints (A) of x, y, z."""
        state = self.state()
        return [state[n]['setpoint_a'] for n in 'xyz']

    def outputs(self):
        """Return the output states of x, y, z."""
        state = self.state()
        return [state[n]['output_on'] for n in 'xyz']

    def sets_since(self, t):
        """Return {axis: [current_a of every set request received after time t]}."""
        return {n: [e['current_a'] for e in self.ask(op='log', port=n, since=t)['log']
                    if 'current_a' in e] for n in 'xyz'}

    def fault(self, port, kind, **options):
        """Arm a fault on one supply."""
        assert self.ask(op='fault', port=port, kind=kind, **options) == {'ok': True}

    def stop(self):
        """Quit and wait (kill if it hangs)."""
        if self.popen.poll() is None:
            try:
                self.popen.stdin.write('{"op": "quit"}\n')
                self.popen.stdin.flush()
                self.popen.wait(5)
            except (OSError, subprocess.TimeoutExpired):
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait()


def node_params_file(tmp_path, ports, **params):
    """Write a params file for coils_node (config/coils.yaml overridden by params)."""
    import yaml
    base = yaml.safe_load((ROOT / 'config' / 'coils.yaml').read_text())
    values = base['coils_node']['ros__parameters']
    values.update({'ports': [ports[n] for n in 'xyz'], **params})
    path = tmp_path / 'coils_params.yaml'
    path.write_text(yaml.safe_dump(base))
    return path


@pytest.fixture
def coil_rig(tmp_path):
    """Return a factory: coil_rig(dialect, baud, **params) -> (emulators, node process)."""
    started = []

    def make(dialect='dxkdp', baud=9600, emulator_args=(), **params):
        emulators = Emulators(tmp_path, dialect, baud, emulator_args)
        started.append(emulators)
        params_file = node_params_file(tmp_path, emulators.ports, dialect=dialect, baud=baud,
                                       **params)
        node = Process([sys.executable, '-m', 'tentacle_coils.coils_node', '--ros-args',
                        '--params-file', str(params_file)], str(tmp_path / 'coils_node.log'))
        started.append(node)
        return emulators, node

    yield make
    for thing in reversed(started):
        thing.stop()


@pytest.fixture
def probe():
    """Return a ROS node in this process that talks to the rig (see rig_probe.py)."""
    from rig_probe import RigProbe
    handle = RigProbe()
    yield handle
    handle.close()
