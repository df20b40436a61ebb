"""The schedule player as a state machine, on a virtual clock against a scripted rig."""

from dataclasses import dataclass, field

import numpy as np
import pytest
from tentacle_planner.player import (commanded_axes, Phase, play_steps, Player, PlayStep,
                                     Seen, Settings)
from tentacle_planner.schedule_check import CoilLimits
from tentacle_planner.shape_control import in_limits

TICK_S = 0.01


@dataclass
class Step:  # the ScheduleStep fields play_steps reads
    insertion_m: float
    field_t: tuple
    backbone_m: float | None = None


@dataclass
class Schedule:
    steps: list


def schedule(count=5, step_m=0.001):
    return Schedule([Step((k + 1) * step_m, (0.0, 0.002 * (k + 1), 0.0)) for k in range(count)])


@dataclass
class ScriptedRig:
    """Stages at a fixed speed, a field that follows at a slew rate, read back at 10 Hz."""

    speed_m_s: float = 0.005
    slew_t_s: float = 0.1
    readback_s: float = 0.1
    position_m: float = 0.0
    field_t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    target_m: float = 0.0
    command_t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    stalled: bool = False
    supply_dead: bool = False
    seen: Seen = field(default_factory=Seen)
    targets: list = field(default_factory=list)
    stops: int = 0
    _next_read: float = 0.0

    def apply(self, command):
        if command.field_t is not None:
            self.command_t = np.array(command.field_t, dtype=float)
        for axis, target in command.targets_m.items():
            self.target_m = target
            self.targets.append((axis, target))
        if command.stop_axes:
            self.stops += 1
            self.target_m = self.position_m

    def advance(self, now, dt):
        if not self.stalled:
            move = np.clip(self.target_m - self.position_m, -self.speed_m_s * dt,
                           self.speed_m_s * dt)
            self.position_m += move
        if not self.supply_dead:
            self.field_t += np.clip(self.command_t - self.field_t, -self.slew_t_s * dt,
                                    self.slew_t_s * dt)
        moving = abs(self.target_m - self.position_m) > 1e-12 and not self.stalled
        if now >= self._next_read:
            self._next_read = now + self.readback_s
            if not self.supply_dead:
                self.seen.field_t, self.seen.field_at = self.field_t.copy(), now
            self.seen.positions_m['inserter'] = self.position_m
            self.seen.velocities_m_s['inserter'] = self.speed_m_s if moving else 0.0
            self.seen.positions_at['inserter'] = now


def run(player, rig, until, start_at=0.0, events=(), stop_at=(Phase.DONE, Phase.ABORTED)):
    """
    Tick the player and the rig on a virtual clock until a phase in stop_at or ``until``.

    :param events: [(time, callable(now) -> Command or None)], in any order
    :return: (the time it stopped, every line the player said)
    """
    now, said, pending = start_at, [], sorted(events, key=lambda e: e[0])
    rig.advance(now, 0.0)
    while now < until and player.phase not in stop_at:
        while pending and pending[0][0] <= now:
            command = pending.pop(0)[1](now)
            if command is not None:
                rig.apply(command)
                said += command.said
        command = player.update(now, rig.seen)
        rig.apply(command)
        said += command.said
        now += TICK_S
        rig.advance(now, TICK_S)
    return now, said


def started(steps=None, settings=Settings(), retract=False, **rig_kw):
    start, play = play_steps(steps or schedule(), retract=retract)
    player = Player(start, play, settings)
    rig = ScriptedRig(**rig_kw)
    if retract:
        rig.position_m = rig.target_m = play[0].targets_m['inserter']
    rig.advance(0.0, 0.0)
    rig.apply(player.start(0.0, rig.seen))
    return player, rig


def test_a_run_plays_every_step_in_order_and_holds_the_last_field():
    player, rig = started()
    end, said = run(player, rig, 30.0)
    assert player.phase is Phase.DONE and said[-1] == 'done: every step played'
    assert [t for _, t in rig.targets] == pytest.approx([0.001 * k for k in range(1, 6)])
    assert player.hold().field_t == pytest.approx([0.0, 0.010, 0.0])
    # each step: the 1 mm move (0.2 s), the read-back (<= 0.1 s) and the dwell (0.3 s)
    assert 5 * 0.5 <= end <= 5 * (0.2 + 0.1 + 0.3) + 0.1


def test_a_retraction_plays_the_steps_backwards_to_nothing_inserted_and_zero_field():
    player, rig = started(retract=True)
    assert player.start_m == {'inserter': pytest.approx(0.005)}
    run(player, rig, 30.0)
    assert [t for _, t in rig.targets] == pytest.approx([0.005, 0.004, 0.003, 0.002, 0.001, 0.0])
    assert player.phase is Phase.DONE and np.all(player.field_t == 0)


def test_a_run_will_not_start_where_it_does_not_begin():
    start, play = play_steps(schedule())
    player = Player(start, play)
    with pytest.raises(ValueError, match='no position from the inserter'):
        player.start(0.0, Seen())
    seen = Seen(positions_m={'inserter': 0.004}, positions_at={'inserter': 0.0})
    with pytest.raises(ValueError, match=r'inserter is at 4\.00 mm; this run starts at 0\.00'):
        player.start(0.0, seen)
    assert player.phase is Phase.IDLE


def test_a_run_that_moves_the_backbone_will_not_start_without_its_position():
    # A coiling run starts the backbone wherever it is, but commands it from its first step:
    # without a reading from it, the run would pause at once ('no /backbone/state').
    coiling = Schedule([Step(0.08, (0.0, 0.002, 0.0), backbone_m=0.08 - 0.0025 * k)
                        for k in range(3)])
    start, play = play_steps(coiling, ('inserter', 'backbone'))
    assert start == {'inserter': 0.0}
    assert commanded_axes(coiling, ('inserter', 'backbone')) == ['inserter', 'backbone']
    assert commanded_axes(coiling) == commanded_axes(schedule(), ('inserter', 'backbone')) \
        == ['inserter']   # the backbone not allowed, or no reach in the schedule
    player = Player(start, play)
    seen = Seen(positions_m={'inserter': 0.0}, positions_at={'inserter': 0.0})
    with pytest.raises(ValueError, match='no position from the backbone'):
        player.start(0.0, seen)
    assert player.phase is Phase.IDLE
    seen.positions_m['backbone'], seen.positions_at['backbone'] = 0.08, 0.0
    assert player.start(0.0, seen).targets_m == {'inserter': 0.08, 'backbone': 0.08}


def test_pause_holds_the_field_and_sends_no_target_until_resumed():
    player, rig = started()
    held = {}

    def pause(now):
        command = player.pause(now)
        held['field'], held['targets'] = command.field_t.copy(), len(rig.targets)
        return command

    end, said = run(player, rig, 5.0, events=[(1.05, pause)])
    assert player.phase is Phase.PAUSED and end == pytest.approx(5.0, abs=0.02)
    assert len(rig.targets) == held['targets']          # no new target while paused
    assert np.array_equal(player.hold().field_t, held['field'])
    assert rig.stops == 0                                 # pause is not a stop
    resumed = player.resume(end, rig.seen)
    rig.apply(resumed)
    _, said = run(player, rig, 30.0, start_at=end)
    assert player.phase is Phase.DONE
    assert [t for _, t in rig.targets][-1] == pytest.approx(0.005)


def test_abort_commands_zero_field_and_stops_a_stage_that_moves_only():
    player, rig = started()
    _, said = run(player, rig, 5.0, events=[(0.1, lambda now: player.abort(now))])
    assert player.phase is Phase.ABORTED and rig.stops == 1   # mid-move: stopped
    assert np.all(rig.command_t == 0) and said[-1].startswith('aborted at step')
    with pytest.raises(ValueError, match='nothing to resume'):
        player.resume(1.0, rig.seen)
    player, rig = started()
    while player.phase is not Phase.DWELL:
        rig.apply(player.update(rig.seen.field_at + TICK_S, rig.seen))
        rig.advance(rig.seen.field_at + 0.1, 0.1)
    rig.apply(player.abort(rig.seen.field_at, seen=rig.seen))
    assert rig.stops == 0 and np.all(rig.command_t == 0)   # at rest: left homed
    player.release()   # zero read back: no longer a commander of the coils
    assert player.hold().field_t is None
    with pytest.raises(ValueError, match='only a finished run at zero field'):
        started()[0].release()


def test_the_estop_pauses_the_run_and_a_resume_is_refused_while_it_is_on():
    player, rig = started()

    def estop(now):
        rig.seen.estop = True
    end, said = run(player, rig, 3.0, events=[(0.9, estop)], stop_at=(Phase.PAUSED,))
    assert player.phase is Phase.PAUSED and player.reason == 'the estop is on'
    assert any(line.startswith('paused at step') and 'estop' in line for line in said)
    with pytest.raises(ValueError, match='not resumed: the estop is on'):
        player.resume(end, rig.seen)
    rig.seen.estop = False
    rig.apply(player.resume(end, rig.seen))
    run(player, rig, 30.0, start_at=end)
    assert player.phase is Phase.DONE


def test_a_stalled_stage_pauses_the_run_at_its_deadline_saying_where_it_is():
    player, rig = started(settings=Settings(settle_timeout_s=1.0))

    def stall(now):
        rig.stalled = True
    end, said = run(player, rig, 10.0, events=[(1.1, stall)], stop_at=(Phase.PAUSED,))
    assert player.phase is Phase.PAUSED
    assert 'not there after' in player.reason and 'the inserter at' in player.reason
    # the step under way started before 1.1 s: its deadline is its move's own time (1 mm at
    # 5 mm/s) plus the settle timeout after that
    assert 1.1 < end <= 1.1 + 0.2 + 1.0 + TICK_S


def test_a_supply_that_stops_answering_pauses_the_run_or_aborts_it_as_configured():
    for abort, phase in ((False, Phase.PAUSED), (True, Phase.ABORTED)):
        player, rig = started(settings=Settings(feedback_timeout_s=0.5, abort_on_fault=abort))

        def die(now):
            rig.supply_dead = True
        end, said = run(player, rig, 10.0, events=[(1.0, die)],
                        stop_at=(Phase.PAUSED, Phase.ABORTED))
        assert player.phase is phase and 'no /coils/field for' in player.reason
        assert 1.0 - 0.1 + 0.5 <= end <= 1.0 + 0.5 + 2 * TICK_S   # the last reading, + 0.5 s


def test_a_closed_loop_correction_is_held_and_carried_to_the_next_steps():
    limits = CoilLimits(max_field_t=0.009)
    start, play = play_steps(schedule())
    player = Player(start, play, field_limit=lambda b: in_limits(b, limits))
    rig = ScriptedRig()
    rig.advance(0.0, 0.0)
    rig.apply(player.start(0.0, rig.seen))
    while player.phase is not Phase.DWELL:
        rig.apply(player.update(rig.seen.field_at + TICK_S, rig.seen))
        rig.advance(rig.seen.field_at + 0.1, 0.1)
    corrected = player.adjust_field(player.field_t + [0.0005, 0.0, 0.0])
    assert corrected.field_t == pytest.approx([0.0005, 0.002, 0.0])
    run(player, rig, 30.0, start_at=rig.seen.field_at)
    assert player.field_t == pytest.approx([0.0005, 0.009, 0.0])   # carried, and limited
    player.phase = Phase.DWELL   # a loop asking for more than a step's change gets a step's
    player.settings = Settings(max_correction_t=0.001)
    assert player.adjust_field(player.step.field_t + [0.005, -0.003, 0.0]).field_t == \
        pytest.approx(player.step.field_t + [0.001, -0.001, 0.0])


def test_busy_keeps_a_step_dwelling():
    player, rig = started()
    now = 0.0
    while player.phase is not Phase.DWELL:
        rig.apply(player.update(now, rig.seen))
        now += TICK_S
        rig.advance(now, TICK_S)
    for _ in range(100):   # a second past the dwell: still on step 1 while busy
        player.update(now, rig.seen, busy=True)
        now += TICK_S
        rig.advance(now, TICK_S)
    assert player.phase is Phase.DWELL and player.step.index == 1
    player.update(now, rig.seen)
    assert player.step.index == 2


def test_a_run_needs_steps_and_can_start_once():
    with pytest.raises(ValueError, match='at least one step'):
        Player({}, [])
    player = Player({}, [PlayStep(1, 0.001, {'inserter': 0.001}, np.zeros(3))])
    seen = Seen(positions_m={'inserter': 0.0}, positions_at={'inserter': 0.0})
    player.start(0.0, seen)
    with pytest.raises(ValueError, match='start a new run'):
        player.start(1.0, seen)


def test_the_dwell_left_counts_down_from_the_arrival_and_is_none_otherwise():
    player, rig = started(settings=Settings(dwell_s=0.25))
    assert player.dwell_left_s(0.0) is None                     # moving
    now, _ = run(player, rig, 10.0, stop_at=(Phase.DWELL,))
    arrived = player.since
    assert player.dwell_left_s(arrived) == pytest.approx(0.25)
    assert player.dwell_left_s(arrived + 0.2) == pytest.approx(0.05)
    player.pause(now)
    assert player.dwell_left_s(now) is None                     # paused: nothing to end


def test_a_first_step_far_from_the_start_has_its_move_time_to_arrive():
    far = Schedule([Step(0.08, (0.0, 0.002, 0.0)), Step(0.081, (0.0, 0.004, 0.0))])
    player, rig = started(far, Settings(settle_timeout_s=2.0, speed_m_s=0.005))
    end, said = run(player, rig, 30.0)
    assert player.phase is Phase.DONE, said      # 16 s of move, not paused after 2 s
    assert end > 16.0


def test_a_retraction_ends_at_zero_field_whatever_correction_it_carried():
    player, rig = started(retract=True)
    run(player, rig, 10.0, stop_at=(Phase.DWELL,))
    rig.apply(player.adjust_field(player.field_t + np.array([0.0, 0.001, 0.0])))
    assert np.any(player.bias_t)                   # carried to the later steps ...
    run(player, rig, 30.0)
    assert player.phase is Phase.DONE
    assert not np.any(player.field_t) and not np.any(rig.command_t)   # ... but not to zero


def test_a_finished_run_lets_go_only_once_its_zero_reads_back_after_it_was_sent():
    player, rig = started()
    run(player, rig, 10.0, stop_at=(Phase.DWELL,))
    assert not player.zero_read_back(rig.seen)                 # running
    command = player.abort(rig.seen.field_at, seen=rig.seen)
    rig.apply(command)
    assert not player.zero_read_back(rig.seen)                 # the old field, read before
    now = rig.seen.field_at
    while np.abs(rig.seen.field_t).max() > player.settings.field_tolerance_t:
        now += 0.1
        rig.advance(now, 0.1)                                  # the supplies ramp down
    assert player.zero_read_back(rig.seen)
