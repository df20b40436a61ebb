"""
Playing a schedule, as a state machine on a clock it is given: what to command, when to go on.

``Player`` holds the steps of a run (a schedule's, forwards to insert, backwards to retract)
and is driven by ``update(now, seen)``: the time (s, any monotonic clock: the node's, or a
test's virtual one) and what the rig last reported (``Seen``: the field read back, the stages'
positions, the estop, the drivers' faults). It answers with what the rig should hold (a field
and the stages' targets) and what it says. A step is commanded, waited for until the stages
are within ``position_tolerance_m`` and still and the field read back within
``field_tolerance_t`` (each with a deadline), dwelt on, and the next one follows. While a
step dwells a closed loop may change its field (``adjust_field``); the change is carried to
the steps after it.

Faults (the estop, a driver's error, a reading that stops coming, a stage or field that
misses its deadline) pause the run, hold everything where it is and say why (or abort it,
with ``abort_on_fault``). ``pause`` holds the field and the stages where they are (a move in
flight finishes; no stop, no homing); ``resume`` commands the paused step again;
``abort`` commands zero field and asks the node to stop the stages. A finished insertion
holds its last field (the body stays in shape) until it is retracted or aborted.
Pure: no rclpy. Units: s, m, T.
"""

from dataclasses import dataclass, field
import enum

import numpy as np


class Phase(enum.Enum):
    """Where a run is."""

    IDLE = 'idle'          # nothing started
    MOVING = 'moving'      # a step commanded, waiting for the stages and the field
    DWELL = 'dwell'        # settled: dwelling (a closed loop corrects here)
    PAUSED = 'paused'      # holding where it is (asked, or a fault)
    DONE = 'done'          # every step played; the last field held
    ABORTED = 'aborted'    # zero field commanded, stages stopped


@dataclass(frozen=True)
class PlayStep:
    """One step as played: stage targets (m, stage positions) and the planned field (T)."""

    index: int                 # 1-based, in the schedule's insertion order
    inserted_m: float          # the inserted length it plays
    targets_m: dict            # {axis: stage position, m}
    field_t: np.ndarray        # (3,) T, frame coils


@dataclass(frozen=True)
class Settings:
    """How a run is paced and when it counts as stuck."""

    dwell_s: float = 0.3                 # at a settled step, before the next
    start_tolerance_m: float = 5e-4      # a stage this near where the run starts may start
    position_tolerance_m: float = 2e-5   # a stage within this of its target, and
    still_m_s: float = 1e-4              # ... slower than this, has arrived
    field_tolerance_t: float = 2e-4      # the field read back within this per axis
    settle_timeout_s: float = 2.0        # a step's deadline beyond its move's own time
    speed_m_s: float = 0.005             # the stages' speed (a move's expected time)
    feedback_timeout_s: float = 1.0      # a reading older than this is a fault
    abort_on_fault: bool = False         # a fault aborts instead of pausing
    max_correction_t: float = np.inf     # a closed loop's field off the plan's, per axis


@dataclass
class Seen:
    """What the rig last reported, with when each was received (the player's clock, s)."""

    field_t: np.ndarray | None = None
    field_at: float = -np.inf
    positions_m: dict = field(default_factory=dict)    # {axis: m}
    velocities_m_s: dict = field(default_factory=dict)  # {axis: m/s}
    positions_at: dict = field(default_factory=dict)    # {axis: s}
    estop: bool = False
    faults: tuple = ()          # the drivers' errors, in words


@dataclass
class Command:
    """What the rig should hold now, and what the player says."""

    field_t: np.ndarray | None          # hold this field (re-send it); None: command none
    targets_m: dict                     # {axis: stage position, m}; {} none
    stop_axes: bool = False             # stop every stage now (abort)
    said: list = field(default_factory=list)


def _mt(field_t):
    return '[' + ', '.join(f'{v * 1e3:.2f}' for v in field_t) + ']'


def play_steps(schedule, axes=('inserter',), insertion_offset_m=0.0, retract=False):
    """
    Return (where the stages start, the PlaySteps) of a schedule: {axis: m}, [PlayStep].

    Insertion order from nothing inserted, or backwards from the last step to nothing
    inserted and zero field to retract.

    :param axes: the stages the run commands: 'inserter' (the inserted length plus
        ``insertion_offset_m``) and, for a schedule with backbone reaches, 'backbone'
    """
    steps = []
    for i, step in enumerate(schedule.steps, start=1):
        targets = {'inserter': step.insertion_m + insertion_offset_m}
        if 'backbone' in axes and step.backbone_m is not None:
            targets['backbone'] = step.backbone_m
        steps.append(PlayStep(i, step.insertion_m, targets, np.asarray(step.field_t, float)))
    home = {'inserter': insertion_offset_m}
    if retract:
        return steps[-1].targets_m, steps[::-1] + [PlayStep(0, 0.0, home, np.zeros(3))]
    return home, steps


def commanded_axes(schedule, axes=('inserter',)):
    """Return the stages a run of a schedule commands, of axes: [axis] (play_steps')."""
    return _commanded(*play_steps(schedule, axes))


def _commanded(start, steps):
    """Return the stages a run of play_steps' (start, steps) commands, in order."""
    return list(dict.fromkeys([*start, *(a for s in steps for a in s.targets_m)]))


class Player:
    """One run of steps on the rig."""

    def __init__(self, start_m, steps, settings=Settings(), field_limit=None):
        """
        Hold the steps; nothing is commanded until start.

        :param start_m: {axis: m} where the stages must stand to start (play_steps)
        :param field_limit: a callable (3,) T -> (3,) T that keeps a field within the coils'
            limits (a closed loop's corrections pass through it), or None
        """
        if not steps:
            raise ValueError('a run needs at least one step')
        self.start_m, self.steps, self.settings = dict(start_m), list(steps), settings
        self.field_limit = field_limit or (lambda b: b)
        self.phase, self.index, self.reason = Phase.IDLE, 0, ''
        self.field_t = None            # the field held now, T
        self.bias_t = np.zeros(3)      # a closed loop's correction, carried to later steps
        self.since = 0.0               # when the phase began (the player's clock, s)
        self._deadline = np.inf
        self._sent_at = 0.0            # when the step's field and targets were commanded
        self._targets = {}

    @property
    def step(self):
        """Return the PlayStep being played (the last one once done)."""
        return self.steps[min(self.index, len(self.steps) - 1)]

    @property
    def running(self):
        """Return whether a run is under way (moving or dwelling)."""
        return self.phase in (Phase.MOVING, Phase.DWELL)

    def start(self, now, seen):
        """Start at the first step; return the Command. Refused (ValueError) unless idle."""
        if self.phase is not Phase.IDLE:
            raise ValueError(f'the run is {self.phase.value}: start a new run to play again')
        # Every stage the run will command, not only those it starts from (a coiling run
        # starts the backbone wherever it is): without a reading the run would pause at once.
        for axis in _commanded(self.start_m, self.steps):
            if seen.positions_m.get(axis) is None:
                raise ValueError(f'no position from the {axis} yet: is its node running?')
        for axis, start in self.start_m.items():
            where = seen.positions_m[axis]
            if abs(where - start) > self.settings.start_tolerance_m:
                raise ValueError(f'the {axis} is at {where * 1e3:.2f} mm; this run starts at '
                                 f'{start * 1e3:.2f} mm (home it there, or play the other way)')
        return self._command_step(now, 0, f'started: {len(self.steps)} steps')

    def _command_step(self, now, index, line):
        self.index, self.phase, self.reason = index, Phase.MOVING, ''
        step = self.step
        # A zero field is off, not a place to carry a correction to: a retraction ends at zero.
        self.field_t = self.field_limit(step.field_t + self.bias_t) if np.any(step.field_t) \
            else np.zeros(3)
        self._targets = dict(step.targets_m)
        self.since = self._sent_at = now
        self._deadline = now + self._expected_move_s() + self.settings.settle_timeout_s
        return Command(self.field_t, self._targets, said=[line] if line else [])

    def _expected_move_s(self):
        # From where the run starts to its first step too: ch6's first step inserts 80 mm.
        before = self.start_m if self.index == 0 else self.steps[self.index - 1].targets_m
        return max((abs(t - before.get(a, t)) for a, t in self._targets.items()),
                   default=0.0) / self.settings.speed_m_s

    def hold(self):
        """Return the Command that holds the field held now (re-sent: the coils' watchdog)."""
        return Command(self.field_t, {})

    def arrived(self, seen):
        """Return [] when the stages and the field have reached the step; else what has not."""
        s = self.settings
        missing = []
        for axis, target in self._targets.items():
            where = seen.positions_m.get(axis)
            if where is None or seen.positions_at.get(axis, -np.inf) < self._sent_at:
                missing.append(f'no {axis} position since the command')
            elif abs(where - target) > s.position_tolerance_m or \
                    abs(seen.velocities_m_s.get(axis, 0.0)) > s.still_m_s:
                missing.append(f'the {axis} at {where * 1e3:.3f} mm, not {target * 1e3:.3f} mm')
        if seen.field_t is None or seen.field_at < self._sent_at:
            missing.append('no field reading since the command')
        elif np.max(np.abs(seen.field_t - self.field_t)) > s.field_tolerance_t:
            missing.append(f'the field reads {_mt(seen.field_t)} mT, not {_mt(self.field_t)} mT')
        return missing

    def fault_of(self, now, seen):
        """Return what is wrong with the rig now ('' nothing): estop, faults, stale readings."""
        if seen.estop:
            return 'the estop is on'
        if seen.faults:
            return '; '.join(seen.faults)
        late = self.settings.feedback_timeout_s
        if now - seen.field_at > late:
            return f'no /coils/field for {min(now - seen.field_at, 1e6):.1f} s'
        for axis in self._targets:
            age = now - seen.positions_at.get(axis, -np.inf)
            if age > late:
                return f'no /{axis}/state for {min(age, 1e6):.1f} s'
        return ''

    def update(self, now, seen, busy=False):
        """
        Return the Command for this moment.

        :param busy: a closed loop is still correcting this step: dwell on
        """
        if not self.running:
            return self.hold()
        fault = self.fault_of(now, seen)
        if fault:
            return self._fault(now, fault, seen)
        if self.phase is Phase.MOVING:
            missing = self.arrived(seen)
            if not missing:
                self.phase, self.since = Phase.DWELL, now
            elif now > self._deadline:
                return self._fault(now, f'step {self.step.index}: not there after '
                                        f'{now - self._sent_at:.1f} s: ' + '; '.join(missing),
                                   seen)
            return self.hold()
        if now - self.since < self.settings.dwell_s or busy:
            return self.hold()
        if self.index + 1 >= len(self.steps):
            self.phase, self.index = Phase.DONE, len(self.steps)
            return Command(self.field_t, {}, said=['done: every step played'])
        return self._command_step(now, self.index + 1, '')

    def dwell_left_s(self, now):
        """Return the time, s, until the dwell at this step is over; None when not dwelling."""
        if not self.running or self.phase is not Phase.DWELL:
            return None
        return self.since + self.settings.dwell_s - now

    def adjust_field(self, field_t):
        """
        Hold a corrected field for the step dwelling now (a closed loop); carried on.

        The correction stays within ``max_correction_t`` of the planned field on each axis
        (the coils' largest change per step: a loop never moves the field further from the
        plan than one step may), and the field within the coils' limits.
        """
        if self.phase is not Phase.DWELL:
            return self.hold()
        limit = self.settings.max_correction_t
        planned = self.step.field_t
        wanted = np.clip(np.asarray(field_t, dtype=float) - planned, -limit, limit)
        self.field_t = self.field_limit(planned + wanted)
        self.bias_t = self.field_t - planned
        return Command(self.field_t, {})

    def _fault(self, now, reason, seen=None):
        if self.settings.abort_on_fault:
            command = self.abort(now, reason, seen)
        else:
            self.phase, self.reason, self.since = Phase.PAUSED, reason, now
            command = self.hold()
        command.said.append(f'{self.phase.value} at step {self.step.index}: {reason}')
        return command

    def pause(self, now, reason='asked to'):
        """Hold the field and the stages where they are (a move in flight finishes)."""
        if not self.running:
            raise ValueError(f'nothing to pause: the run is {self.phase.value}')
        self.phase, self.reason, self.since = Phase.PAUSED, reason, now
        return Command(self.field_t, {}, said=[f'paused at step {self.step.index}: {reason}'])

    def resume(self, now, seen):
        """Play the paused step again, from its command; refused while the rig is at fault."""
        if self.phase is not Phase.PAUSED:
            raise ValueError(f'nothing to resume: the run is {self.phase.value}')
        fault = self.fault_of(now, seen)
        if fault:
            raise ValueError(f'not resumed: {fault}')
        return self._command_step(now, self.index, f'resumed at step {self.step.index}')

    def zero_read_back(self, seen):
        """Return whether a finished run's zero field reads back, after it was sent (release)."""
        return self.phase in (Phase.ABORTED, Phase.DONE) and self.field_t is not None and \
            not np.any(self.field_t) and seen.field_t is not None and \
            seen.field_at > self.since and \
            np.abs(seen.field_t).max() <= self.settings.field_tolerance_t

    def release(self):
        """
        Stop commanding the field: once an aborted run's (or a retraction's) zero is read back.

        The player then no longer publishes field commands, so another commander (a lab
        script, rig-command) may take the coils without meeting the player's zero.
        """
        if self.phase not in (Phase.ABORTED, Phase.DONE) or self.field_t is None or \
                np.any(self.field_t != 0.0):
            raise ValueError('only a finished run at zero field lets go of the coils')
        self.field_t = None

    def abort(self, now, reason='asked to', seen=None):
        """
        Command zero field and stop the stages that move; the run ends.

        A stage at rest is left as it is (a stop would leave it to be homed again): one that
        moves, or was sent a target not yet reached, is stopped.
        """
        moving = self.phase is Phase.MOVING or (seen is not None and any(
            abs(v) > self.settings.still_m_s for v in seen.velocities_m_s.values()))
        self.phase, self.reason, self.since = Phase.ABORTED, reason, now
        self.field_t = np.zeros(3)
        return Command(self.field_t, {}, stop_axes=moving,
                       said=[f'aborted at step {self.step.index}: {reason}'])
