"""Cross-process test rig: emulated supplies and the coils node as real processes over DDS.

Every run claims a private ROS_DOMAIN_ID (a lock file per domain, so parallel runs on one
machine never share one) with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, before rclpy is
imported. Every process a test starts is stopped when the test ends.
"""

import fcntl
import os
import pathlib
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

from tentacle_sim.sim_rig import CoilRig  # noqa: E402 (after the environment is set)


def wait_for(predicate, timeout_s=5.0, period_s=0.01):
    """Return True as soon as predicate() is true, False after timeout_s."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period_s)
    return False


@pytest.fixture
def coil_rig(tmp_path):
    """Return a factory: coil_rig(dialect, baud, **params) -> (emulators, node process)."""
    started = []

    def make(dialect='dxkdp', baud=9600, emulator_args=(), **params):
        rig = CoilRig(tmp_path, ROOT / 'config' / 'coils.yaml', dialect, baud, emulator_args,
                      ROOT, **params)
        started.append(rig)
        return rig.emulators, rig.node

    yield make
    for rig in started:
        rig.stop()


@pytest.fixture
def probe():
    """Return a ROS node in this process that talks to the rig (see rig_probe.py)."""
    from rig_probe import RigProbe
    handle = RigProbe()
    yield handle
    handle.close()
