"""Emulated supplies on real pseudo-terminals for the driver tests."""

import pytest
from tentacle_sim import waiting
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


@pytest.fixture
def wait_for():
    """Return a poller that waits until a predicate holds (3 s by default)."""
    return lambda condition, timeout_s=3.0: waiting.wait_for(condition, timeout_s)
