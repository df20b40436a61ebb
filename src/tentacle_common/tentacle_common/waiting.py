"""
Waiting for a condition in tests and benches: checked once more at the deadline, lateness said.

A poller that oversleeps its deadline (a stalled machine, a busy core, a process paused) must
not report a condition as failed that it never looked at after the deadline: ``wait_for``
always checks once more when the deadline has passed, and a failed wait says how late that
last check came, so a stall of the waiting process is told apart from a condition that
really did not hold.
"""

import time


class Waited:
    """The outcome of a wait: true when the condition held; says how long and how late."""

    def __init__(self, held, waited_s, late_s, timeout_s):
        """Record whether it held, after how long (s) and how late the last check came (s)."""
        self.held, self.waited_s, self.late_s, self.timeout_s = held, waited_s, late_s, timeout_s

    def __bool__(self):
        """Return whether the condition held."""
        return self.held

    def __repr__(self):
        """Say what happened (shown by a failed assert)."""
        if self.held:
            return f'Waited(held after {self.waited_s:.3f} s)'
        return (f'Waited(not held: last checked {self.late_s:.3f} s after the '
                f'{self.timeout_s:g} s deadline)')


def wait_for(condition, timeout_s=5.0, period_s=0.01):
    """
    Return a Waited, true as soon as condition() holds, false if it still fails after timeout_s.

    :param timeout_s: how long to wait (s); the condition is checked once more after it
    :param period_s: how long to sleep between checks (s)
    """
    start = time.monotonic()
    deadline = start + timeout_s
    while True:
        held = bool(condition())
        now = time.monotonic()
        if held or now >= deadline:
            return Waited(held, now - start, max(0.0, now - deadline), timeout_s)
        time.sleep(min(period_s, deadline - now))
