"""
Cross-process test rig: emulated supplies and the coils node as real processes over DDS.

Every process a test starts is stopped when the test ends.
"""

import pathlib
import subprocess
import sys

import pytest
from rig_support import ROOT  # sets the private ROS domain before anything imports rclpy
from tentacle_sim.sim_rig import CoilRig


@pytest.fixture(scope='session', autouse=True)
def clean_shared_memory():
    """After the run, remove the DDS shared-memory segments of processes that were killed."""
    yield
    fastdds = pathlib.Path(sys.executable).parent / 'fastdds'
    if fastdds.exists():  # removes only segments whose owner process is gone
        subprocess.run([str(fastdds), 'shm', 'clean'], capture_output=True, timeout=30)


@pytest.fixture
def coil_rig(tmp_path):
    """Return a factory of (emulators, node process) for a dialect, baud and node params."""
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
    from rig_probe import rig_probe
    handle = rig_probe()
    yield handle
    handle.close()
