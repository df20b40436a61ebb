"""
The drivers against their emulators over real pseudo-terminals: what these tests share.

These tests cross a package boundary (tentacle_coils and tentacle_inserter driven against
tentacle_sim's emulators, which run the drivers' own codecs), so they live here and not in
each package's test/: a test dependency back on tentacle_sim would make the build order
circular.
"""

import pytest
from tentacle_common import waiting
from tentacle_sim.supply_emulator import make_supply as emulated_supply


@pytest.fixture
def emulate(tmp_path):
    """Return a factory of started supply emulators, one per axis name, all of one dialect."""
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
    """Return a poller that waits until a condition holds (5 s by default)."""
    return lambda condition, timeout_s=5.0: waiting.wait_for(condition, timeout_s)
