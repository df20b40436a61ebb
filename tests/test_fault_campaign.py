"""
The reliability campaign (tests/fault_campaign.py) as tests: one per rig it starts.

Every fault the emulators offer and every signal, each with what must hold: read from the
emulated devices, never from the node. `make campaign` prints the same as a table.
"""

from fault_campaign import groups, run_group, table
import pytest

pytestmark = pytest.mark.ros


@pytest.mark.parametrize('key, names', groups(), ids=[key for key, _ in groups()])
def test_campaign(key, names, tmp_path):
    outcomes = run_group(names, tmp_path, progress=lambda text: None)
    failed = [out for out in outcomes if out.problems]
    assert not failed, '\n' + table(outcomes)
