"""What the inserter's tests share: waiting for a condition."""

import pytest
from tentacle_sim import waiting


@pytest.fixture
def wait_for():
    """Return a poller that waits until a condition holds (5 s by default)."""
    return lambda condition, timeout_s=5.0: waiting.wait_for(condition, timeout_s)
