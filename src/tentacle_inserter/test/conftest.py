"""What the inserter's tests share: waiting for a condition."""

import time

import pytest


def _wait_for(condition, timeout_s=5.0):
    """Return True as soon as condition() holds; False if it still fails at timeout_s."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return bool(condition())  # once more at the deadline: a stalled poller is not a failure


@pytest.fixture
def wait_for():
    """Return a poller that waits until a condition holds (5 s by default)."""
    return _wait_for
