"""Emulated supplies on real pseudo-terminals for the driver tests."""

import time

import pytest

from tentacle_sim.supply_emulator import make_supply as emulated_supply


@pytest.fixture
def emulate(tmp_path):
    """Return a factory of started emulators, one per axis name, all of one dialect."""
    started = []

    def make(dialect, names='xyz', **kwargs):
        emus = [emulated_supply(n, dialect, link_path=str(tmp_path / f'coil_{n}'), **kwargs)
                for n in names]
        started.extend(emus)
        return [emu.start() for emu in emus]

    yield make
    for emu in started:
        emu.stop()


def _wait_for(predicate, timeout_s=3.0):
    """Return True as soon as predicate() holds, False after timeout_s."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return False


@pytest.fixture
def wait_for():
    """Return a poller that waits until a predicate holds (3 s by default)."""
    return _wait_for
