"""The campaign's own checks on canned emulator logs: they flag what is wrong, and only that."""

from fault_campaign import faulted_then_next, Outcome, wire_report


class Emulators:
    """What wire_report reads of the emulators: each axis' received-request log."""

    def __init__(self, logs):
        self.logs = logs

    def log(self, axis, since=0.0):
        return [e for e in self.logs.get(axis, []) if e['t'] >= since]


class Rig:
    def __init__(self, logs):
        self.emulators = Emulators(logs)


def curr(t, current_a, **extra):
    return {'t': t, 'command': 'CURR', 'current_a': current_a, **extra}


def refused_window(y_log):
    out = Outcome('test')
    wire_report(out, Rig({'y': y_log}), t0=10.0, refused=(10.1, 11.6))
    return out.problems


def test_a_ramp_down_after_a_reconnect_is_not_a_step_away():
    # What failed once in about 150 runs of 'scpi unplugged 1 s': the two sets before the
    # unplug carried a fault tag (a reply fault spent on a set, which has no reply) though
    # the supply applied them, and leaving them out made the ramp look like a step away.
    log = [curr(9.97, 3.3994), curr(9.996, 3.459, fault='garble'),
           curr(9.997, 3.4939, fault='late'), curr(11.528, 3.4347), curr(11.54, 2.9),
           curr(11.55, 2.4)]
    assert refused_window(log) == []


def test_a_step_away_from_zero_while_refused_is_reported():
    log = [curr(9.99, 3.0), curr(11.5, 2.5), curr(11.51, 2.6)]
    problems = refused_window(log)
    assert len(problems) == 1 and "('y', 2.5, 2.6, '+1.510 s after one at +1.500 s')" in \
        problems[0]


def test_a_set_the_supply_refused_or_never_got_is_not_the_one_it_holds():
    # A NAKed or unanswered (lost) set was not applied: the ramp is judged from the one before.
    log = [curr(9.99, 3.0), curr(9.995, 3.2, fault='nak'), curr(9.996, 3.4, fault='no_reply'),
           curr(11.5, 3.1)]
    problems = refused_window(log)
    assert len(problems) == 1 and "('y', 3.0, 3.1," in problems[0]


def ramp(rate_a_per_s, t0=10.0, start_a=4.0, dt_s=0.002):
    """Return a ramp from start_a to zero at rate_a_per_s, one set every dt_s."""
    steps = int(start_a / (rate_a_per_s * dt_s))
    return [curr(t0 + k * dt_s, max(start_a - rate_a_per_s * dt_s * k, 0.0))
            for k in range(steps + 1)]


def slew_problems(y_log):
    out = Outcome('test')
    wire_report(out, Rig({'y': y_log}), t0=9.0)
    return out.problems


def test_the_slew_check_takes_a_late_stamp_and_still_catches_a_doubled_rate():
    # The exit ramp's first set stamped 11 ms late under a busy core: within the limit.
    late_first = ramp(50.0)
    late_first[0]['t'] += 0.011
    assert slew_problems(late_first) == []
    assert slew_problems(ramp(100.0)) and slew_problems(ramp(100.0, dt_s=0.02))


def test_a_fault_taken_by_a_request_already_on_the_line_counts():
    # y's log from a cold run that 'received nothing for 5 s': the first garbled set arrived
    # 0.04 ms before the scenario began (t0) and was served after the fault was armed.
    t0 = 15312.3320
    log = [curr(15312.3100, 3.10, served_t=15312.3110),
           curr(15312.331957, 3.2025, served_t=15312.3335, fault='garble'),
           curr(15312.350246, 3.2618, served_t=15312.3510, fault='garble'),
           curr(15312.3703, 3.3100, served_t=15312.3710)]
    faulted, after = faulted_then_next(log, t0, 2)
    assert [e['current_a'] for e in faulted] == [3.2025, 3.2618]
    assert [e['current_a'] for e in after] == [3.31]
    # The log since t0 by arrival (as it was read before) holds one of the two: a wait for ever.
    assert faulted_then_next([e for e in log if e['t'] >= t0], t0, 2) is None


def test_an_earlier_scenarios_fault_does_not_count():
    t0 = 20.0
    log = [curr(19.5, 1.0, served_t=19.5, fault='garble'),   # the previous scenario's
           curr(20.01, 1.1, served_t=20.011, fault='garble'),
           curr(20.03, 1.2, served_t=20.031)]
    assert faulted_then_next(log, t0, 2) is None
    assert faulted_then_next(log, t0, 1)[0][0]['current_a'] == 1.1
