"""
One linear axis on a serial line: checked targets, supervised moves, a stop that holds.

``GcodeStage`` drives a Marlin-style firmware (gcode.py) and ``Step1mmStage`` the reference
rig's inserter (step1mm.py); both keep positions in metres and refuse, before anything is
sent, a target that is not finite or is outside [0, max_length]. A gcode move is absolute
(re-sending it after a lost ``ok`` cannot move the axis twice) and supervised: it must end
within its trapezoid's time (trapezoid.py) times ``time_margin`` plus ``slack_s``, or the
axis is stopped (M112, then M999) and the position read back from the device, never assumed.

A firmware counts steps from where it started: after a connect (a board resets when its
USB line opens) or a halt and reset its count says nothing of where the axis is. So an axis
starts unhomed and refuses moves until ``home()`` (there are no end stops: home is "zero is
here", G92 E0); a stop unhomes it again. The same rule holds for both dialects. No target is
ever replayed. A step1mm axis has no reply and no readback: its position is counted, and says
so (``measured``); it moves in whole millimetres and refuses a target between them.

Until the device at the far end has given one valid gcode reply since the port opened, it is
unknown: it may be another firmware (a step1mm stage takes the digits of ``M112`` and
``M114`` as 1 mm moves) or run at another baud. So a gcode connect sends one probe (G90, no
digit a step1mm firmware moves on) and listens; nothing more is ever sent to a device that
has not answered (NeverAnswered), not even a stop.
"""

import math

from tentacle_common.attempts import Attempts
from tentacle_common.errors import DriverError, ExchangeFailed, FrameError, Refused, ReplyTimeout
from tentacle_inserter import gcode, step1mm
from tentacle_inserter.trapezoid import move_time_s, position_at

POLL_S = 0.01  # how often a waiting move looks whether it was cancelled (s)
RESTART_POLL_S = 0.1  # how often a halted firmware is asked whether it is back (s)
STEP1MM_SETTLE_S = 0.02  # a step1mm move is waited for this beyond its expected time (s)
GRID_TOLERANCE_M = 1e-6  # a step1mm target this close to a whole mm is on it (float noise)
# Reply kinds that only a gcode firmware sends (an 'other' line may be anything's noise).
GCODE_REPLIES = ('ok', 'error', 'start', 'position')


class TargetRefused(DriverError):
    """A target was refused before it reached the wire: not finite, or out of range."""


class MoveFailed(DriverError):
    """A move did not finish in its time (stall, slip, lost reply): the axis was stopped."""


class NotHomed(DriverError):
    """A move was asked of an axis whose zero is not known (after a connect or a stop)."""


class MoveStopped(DriverError):
    """A move was cut short by a stop: the axis was halted, and must be homed again."""


class StillHalted(DriverError):
    """After M112 the firmware neither took M999 nor restarted in time: reset the board."""


class NeverAnswered(DriverError):
    """The device gave no valid gcode reply since the port opened: nothing more is sent."""


def check_target(target_m, max_length_m):
    """
    Return target_m as a float if it is a position the axis may go to.

    :raises TargetRefused: not a number, not finite, or outside [0, max_length_m], saying which
    """
    try:
        value = float(target_m)
    except (TypeError, ValueError):
        raise TargetRefused(f'target {target_m!r} is not a number') from None
    if not math.isfinite(value):
        raise TargetRefused(f'target {value} is not finite')
    if not 0.0 <= value <= max_length_m:
        raise TargetRefused(f'target {value:.6g} m is outside [0, {max_length_m:g}] m')
    return value


class GcodeStage:
    """A Marlin-style stage on the E axis, positions in metres."""

    measured = True  # M114 reads the position back

    def __init__(self, line, *, max_length_m, max_speed_m_s, accel_m_s2, steps_per_mm,
                 reply_timeout_s=0.5, retries=2, time_margin=1.5, slack_s=0.5,
                 restart_timeout_s=5.0):
        """
        Bind to a line (a SerialLine); ``connect()`` talks to the firmware.

        :param max_length_m: soft limit: targets in [0, max_length_m]
        :param max_speed_m_s: every move's speed
        :param accel_m_s2: the firmware's acceleration (its setting: the expected times)
        :param steps_per_mm: calibration sent with M92 at connect
        :param reply_timeout_s: longest wait for a reply to a command (not for motion)
        :param time_margin, slack_s: a move may take its trapezoid's time x time_margin +
            slack_s before it is called stalled
        :param restart_timeout_s: longest wait for a firmware that restarts after M112
        """
        self.line = line
        self.max_length_m, self.max_speed_m_s = float(max_length_m), float(max_speed_m_s)
        self.accel_m_s2, self.steps_per_mm = float(accel_m_s2), float(steps_per_mm)
        self.reply_timeout_s = float(reply_timeout_s)
        self.time_margin, self.slack_s = float(time_margin), float(slack_s)
        self.restart_timeout_s = float(restart_timeout_s)
        self.attempts = Attempts(line, retries=retries, max_turnaround_s=reply_timeout_s)
        self.position_m = None  # as last read back (None: unknown)
        self.homed = False
        self.answered = False   # a valid gcode reply came since the port opened
        self._motion = None     # (start m, target m, when it began s) of the move under way

    def check(self, target_m):
        """
        Return target_m (m) as a float if the axis may go there.

        :raises TargetRefused: not a number, not finite, or outside [0, max_length_m]
        """
        return check_target(target_m, self.max_length_m)

    # -- exchanges --------------------------------------------------------------------------
    def _write(self, request):
        """
        Send bytes to a device known to speak gcode; return when they leave the line (s).

        :raises NeverAnswered: it has not answered since the port opened: nothing is sent
        """
        if not self.answered:
            raise NeverAnswered(f'{self.line.path}: the device never answered since the port '
                                f'opened: {request.decode().strip()} not sent; its state is '
                                'unknown')
        return self.line.write(request)

    def _reply(self, deadline):
        """Return (kind, value) of the next reply line; note a device that speaks gcode."""
        kind, value = gcode.parse_reply(self.line.read_until(gcode.TERMINATOR, deadline))
        if kind in GCODE_REPLIES or (kind == 'other' and value.startswith('echo:')):
            self.answered = True
        return kind, value

    def _exchange(self, request, timeout_s):
        """Send one line; return the lines before its ``ok`` (raise Refused on Error:)."""
        self._write(request)
        deadline = self.line.now() + timeout_s
        lines = []
        while True:
            kind, value = self._reply(deadline)
            if kind == 'ok':
                return lines
            if kind == 'error':
                raise Refused(f'{request.decode().strip()}: {value}')
            lines.append((kind, value))

    def _command(self, request):
        """Return _exchange's lines, with the retries of Attempts (commands are idempotent)."""
        return self.attempts.run(request.decode().strip(),
                                 lambda: self._exchange(request, self.reply_timeout_s))

    def read_position(self):
        """Return the position the firmware reports (M114), m; remember it."""
        for kind, value in self._command(gcode.report_position()):
            if kind == 'position':
                self.position_m = value
                return value
        raise Refused('M114: no position line')

    # -- life cycle -------------------------------------------------------------------------
    def connect(self):
        """
        Open the line, halt what still moves, set absolute mode and the calibration; read back.

        A move queued before a line loss, or by a driver process that died, may still be
        running, and nobody is waiting for it any more: unless M400 answers at once (no
        motion), the axis is halted (M112, M999) first. All of that only once the device
        has answered the probe (``_first_contact``).

        :raises NeverAnswered: no valid gcode reply to the one probe (nothing more sent)
        """
        self.line.open()
        self.answered, self.homed = False, False
        self.attempts.resync()
        self._first_contact()
        if not self._idle():
            self._halt()
        self._command(gcode.absolute())
        self._command(gcode.steps_per_mm(self.steps_per_mm))
        self.homed = False
        return self.read_position()

    def _first_contact(self):
        """
        Send one probe (G90) and listen for a valid gcode reply, up to restart_timeout_s.

        A board that resets when its port opens may lose the probe while it boots; it then
        says ``start`` (and echo lines), which is as good an answer: its late chatter is
        drained. Listening is harmless, so a slow board is waited for; sending is not, so
        the probe is never repeated.

        :raises NeverAnswered: nothing valid came: not a gcode firmware at this baud
        """
        self.line.write(gcode.absolute())  # no 1, 2 or 3: no step1mm mapping moves on it
        wait_s = max(self.restart_timeout_s, self.reply_timeout_s)
        deadline = self.line.now() + wait_s
        while True:
            try:
                kind, _ = self._reply(deadline)
            except (FrameError, ReplyTimeout):  # noise (another baud?) or a babbling line
                if self.line.now() >= deadline:
                    raise NeverAnswered(
                        f'{self.line.path}: no gcode reply in {wait_s:g} s to one probe (G90) '
                        f'at {self.line.baud} bit/s: not a gcode firmware (a step1mm stage '
                        'never answers: dialect step1mm), or another baud. Nothing more was '
                        'sent, not even a stop: the axis state is unknown') from None
                continue
            if self.answered:
                if kind != 'ok':  # boot chatter, and the probe's own ok, may still come
                    self.line.discard_input(quiet_s=self.reply_timeout_s)
                return

    def home(self):
        """Call where the axis stands zero (G92 E0): it may move from now on."""
        self._command(gcode.set_position(0.0))
        self.homed = True
        return self.read_position()

    def move_to(self, target_m, cancelled=lambda: False):
        """
        Move to target_m (m) and wait until the axis is there; return the position read back.

        :param cancelled: polled every POLL_S while the axis moves; True stops it at once
        :raises TargetRefused: before anything is sent (check_target)
        :raises NotHomed: before anything is sent: home() first
        :raises MoveFailed: it did not end in time: the axis was stopped, position read back
        :raises MoveStopped: cancelled: the axis was stopped (stop())
        """
        target = self.check(target_m)
        if not self.homed:
            raise NotHomed('the axis is not homed (after a connect or a stop): home it first')
        start = self.position_m if self.position_m is not None else self.read_position()
        allowed = (move_time_s(target - start, self.max_speed_m_s, self.accel_m_s2)
                   * self.time_margin + self.slack_s)
        self._command(gcode.move(target, self.max_speed_m_s))
        self.position_m, self._motion = None, (start, target, self.line.now())
        try:  # once: a stalled move is not waited for twice
            if not self._wait_for_motion(allowed, cancelled):
                self.stop()
                raise MoveStopped(f'move to {target * 1e3:.3f} mm stopped: the axis must be '
                                  'homed again')
        except (ReplyTimeout, Refused) as exc:
            self.stop()
            why = (f'did not finish in {allowed:.2f} s' if isinstance(exc, ReplyTimeout)
                   else 'failed')
            raise MoveFailed(f'move to {target * 1e3:.3f} mm {why} ({exc}): the axis is '
                             'stopped and must be homed again') from None
        finally:
            self._motion = None
        return self.read_position()

    def estimate(self, now=None):
        """
        Return (position m, velocity m/s, measured): read back, or during a move its profile.

        While a move runs the firmware is not asked (it is busy with M400): the position is
        where the trapezoid puts it, and ``measured`` is False.
        """
        motion = self._motion
        if motion is None:
            return self.position_m, 0.0, self.position_m is not None
        start, target, began = motion
        position, velocity = position_at((self.line.now() if now is None else now) - began,
                                         start, target, self.max_speed_m_s, self.accel_m_s2)
        return position, velocity, False

    def motor_off(self):
        """De-energise the motor (M18): the axis may be moved by hand; unhome."""
        self._command(gcode.motor_off())
        self.homed = False

    def _wait_for_motion(self, allowed_s, cancelled):
        """
        Send M400; return True at its ok, False once cancelled.

        :raises ReplyTimeout: no ok within allowed_s
        :raises Refused: an error, or the firmware restarted (it says start)
        """
        self._write(gcode.wait_for_motion())
        deadline = self.line.now() + allowed_s
        while not cancelled():
            if self.line.wait_input(min(deadline, self.line.now() + POLL_S)):
                kind, value = self._reply(deadline)
                if kind == 'ok':
                    return True
                if kind == 'error':
                    raise Refused(f'M400: {value}')
                if kind == 'start':  # it rebooted: the move is forgotten, its count is 0
                    raise Refused('the firmware restarted during the move')
            elif self.line.now() >= deadline:
                raise ReplyTimeout(f'no ok to M400 in {allowed_s:.2f} s')
        return False

    def stop(self):
        """
        Halt at once (M112), reset (M999), read the count back; unhome; return it (m).

        :raises NeverAnswered: the device never answered since the port opened: nothing sent
        """
        self._halt()
        return self.read_position()

    def _idle(self):
        """Return True if M400 is answered ok within the reply timeout (nothing moves)."""
        try:
            self._exchange(gcode.wait_for_motion(), self.reply_timeout_s)
            return True
        except (ReplyTimeout, Refused, FrameError):
            self.attempts.out_of_step = True  # its ok may still come
            return False

    def _halt(self):
        """
        Halt (M112) and reset (M999): the axis stands, unhomed.

        A firmware that must restart after M112 (Marlin's kill) refuses M999 or says
        nothing: it is then asked for its position every RESTART_POLL_S until it answers,
        up to restart_timeout_s, and absolute mode and the calibration are set again (a
        restart forgets them).

        :raises StillHalted: it did not come back in time
        :raises NeverAnswered: the device never answered: nothing sent
        """
        self._write(gcode.halt())   # Marlin answers nothing to M112
        self.homed, self._motion = False, None
        self.attempts.out_of_step = True  # drop whatever a halted firmware still says
        try:
            self._command(gcode.reset())
            return
        except ExchangeFailed:
            pass
        deadline = self.line.now() + self.restart_timeout_s
        while True:
            self.line.discard_input()     # its 'start' and any halted errors
            try:
                self._exchange(gcode.report_position(), self.reply_timeout_s)
                break
            except (Refused, ReplyTimeout, FrameError):
                if self.line.now() >= deadline:
                    raise StillHalted(f'{self.line.path}: halted by M112, M999 refused, and '
                                      f'not restarted in {self.restart_timeout_s:g} s: reset '
                                      'the board') from None
                self.line.wait_input(min(deadline, self.line.now() + RESTART_POLL_S))
        self._command(gcode.absolute())
        self._command(gcode.steps_per_mm(self.steps_per_mm))


class Step1mmStage:
    """
    The reference rig's inserter: a character per 1 mm, no reply; a counted position.

    A move is waited for its expected time (1 mm moves at the firmware's speed and
    acceleration, which the parameters must match), so the next target follows it; a
    cancelled move sends the stop character and counts where the profile had got to. As a
    gcode axis, it starts unhomed, a stop unhomes it, and it moves only once homed.
    """

    measured = False  # no readback: the position is counted

    def __init__(self, line, *, max_length_m, mapping=step1mm.Mapping(), speed_m_s=0.005,
                 accel_m_s2=0.5, start_m=0.0):
        """Bind to a line; the firmware moves at speed_m_s (m/s); count from start_m (m)."""
        self.line, self.max_length_m, self.mapping = line, float(max_length_m), mapping
        self.step_time_s = move_time_s(step1mm.STEP_M, speed_m_s, accel_m_s2)
        self.position_m = float(start_m)
        self.homed = False
        self._motion = None  # (start m, end m, when it began s, how long it takes s)

    def check(self, target_m):
        """
        Return target_m (m) as a float if the axis may go there: in range, on a whole mm.

        :raises TargetRefused: not a number, not finite, outside [0, max_length_m], or
            between whole millimetres (the firmware's resolution is 1 mm)
        """
        target = check_target(target_m, self.max_length_m)
        off_m = abs(target - round(target / step1mm.STEP_M) * step1mm.STEP_M)
        if off_m > GRID_TOLERANCE_M:
            raise TargetRefused(f'target {target * 1e3:.6g} mm is not a whole number of mm: '
                                f'a step1mm axis moves in steps of {step1mm.STEP_M * 1e3:g} mm '
                                '(its resolution)')
        return target

    def connect(self):
        """Open the line and stop whatever may be going on; unhome."""
        self.line.open()
        self.homed = False
        self.line.write(self.mapping.command(0))
        return self.position_m

    def home(self):
        """Count from zero here; return 0. The axis may move from now on."""
        self.position_m = 0.0
        self.homed = True
        return self.position_m

    def move_to(self, target_m, cancelled=lambda: False):
        """
        Send the 1 mm steps towards target_m (whole mm) and wait their expected time.

        :return: the counted position (m)
        :raises TargetRefused: before anything is sent (check)
        :raises NotHomed: before anything is sent: home() first
        :raises MoveStopped: cancelled: the stop character was sent
        """
        target = self.check(target_m)
        if not self.homed:
            raise NotHomed('the axis is not homed (after a connect or a stop): home it first')
        steps = round((target - self.position_m) / step1mm.STEP_M)
        if not steps:
            return self.position_m
        start, end = self.position_m, self.position_m + steps * step1mm.STEP_M
        began = self.line.write(self.mapping.command(1 if steps > 0 else -1) * abs(steps))
        self._motion = (start, end, began, abs(steps) * self.step_time_s)
        try:
            deadline = began + self._motion[3] + STEP1MM_SETTLE_S
            while self.line.now() < deadline:
                if cancelled():
                    self.position_m = self.estimate()[0]
                    self.stop()
                    raise MoveStopped(f'move to {end * 1e3:.0f} mm stopped near '
                                      f'{self.position_m * 1e3:.1f} mm (counted)')
                self.line.wait_input(min(deadline, self.line.now() + POLL_S))  # nothing comes
            self.position_m = end
        finally:
            self._motion = None
        return self.position_m

    def motor_off(self):
        """Stop (the firmware has no motor-off command)."""
        self.stop()

    def estimate(self, now=None):
        """Return (counted position m, velocity m/s, False): never measured."""
        motion = self._motion
        if motion is None:
            return self.position_m, 0.0, False
        start, end, began, duration = motion
        done = min(max(((self.line.now() if now is None else now) - began) / duration, 0.0),
                   1.0)
        return start + (end - start) * done, (end - start) / duration if done < 1 else 0.0, False

    def stop(self):
        """Send the stop character; unhome; return the counted position (sent, not done)."""
        self.homed = False
        self.line.write(self.mapping.command(0))
        return self.position_m
