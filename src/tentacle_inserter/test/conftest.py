"""What the inserter's tests share: waiting for a condition."""

import functools

import pytest
from tentacle_sim import waiting


@pytest.fixture
def wait_for():
    """Return a poller that waits until a condition holds (5 s by default)."""
    return functools.partial(waiting.wait_for, timeout_s=5.0)
