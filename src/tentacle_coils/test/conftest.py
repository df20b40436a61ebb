"""Emulated supplies on real pseudo-terminals for the driver tests."""

import pytest

from tentacle_sim.supply_emulator import EmulatedSupply


@pytest.fixture
def emulate(tmp_path):
    """Return a factory of started emulators, one per axis name, all of one dialect."""
    started = []

    def make(dialect, names='xyz', **kwargs):
        emus = [EmulatedSupply(n, dialect, link_path=str(tmp_path / f'coil_{n}'), **kwargs)
                for n in names]
        started.extend(emus)
        return [emu.start() for emu in emus]

    yield make
    for emu in started:
        emu.stop()
