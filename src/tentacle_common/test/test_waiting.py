"""wait_for on a virtual clock: a stalled poller still looks once more after its deadline."""

import pytest
from tentacle_common import waiting


class StallingClock:
    """time.monotonic and time.sleep where one sleep stalls for ``stall_s`` (a paused process)."""

    def __init__(self, stall_s):
        self.now, self.stall_s = 0.0, stall_s

    def monotonic(self):
        return self.now

    def sleep(self, seconds):
        self.now += max(seconds, self.stall_s)


def test_a_condition_that_came_true_while_the_poller_stalled_is_seen(monkeypatch):
    clock = StallingClock(stall_s=7.0)  # the first sleep oversleeps the 5 s deadline
    monkeypatch.setattr(waiting, 'time', clock)
    result = waiting.wait_for(lambda: clock.now >= 6.0, timeout_s=5.0)
    assert result and result.waited_s == 7.0


def test_a_failed_wait_says_how_late_it_looked_last(monkeypatch):
    clock = StallingClock(stall_s=0.0)
    monkeypatch.setattr(waiting, 'time', clock)
    checks = []
    result = waiting.wait_for(lambda: checks.append(clock.now), timeout_s=1.0, period_s=0.3)
    assert not result and checks == pytest.approx([0.0, 0.3, 0.6, 0.9, 1.0])
    assert result.late_s == 0.0 and 'last checked 0.000 s after the 1 s deadline' in repr(result)
    clock = StallingClock(stall_s=4.0)
    monkeypatch.setattr(waiting, 'time', clock)
    result = waiting.wait_for(lambda: False, timeout_s=1.0)
    assert not result and result.late_s == 3.0 and 'checked 3.000 s after' in repr(result)
