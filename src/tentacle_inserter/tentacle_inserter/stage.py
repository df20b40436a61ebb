"""
One linear axis on a serial line: checked targets, supervised moves, a stop that holds.

``GcodeStage`` drives a Marlin-style firmware (gcode.py) and ``Step1mmStage`` the reference
rig's inserter (step1mm.py); both keep positions in metres and refuse, before anything is
sent, a target that is not finite or is outside [0, max_length]. A gcode move is absolute
(re-sending it after a lost ``ok`` cannot move the axis twice) and supervised: it must end
within its trapezoid's time (trapezoid.py) times ``time_margin`` plus ``slack_s``, or the
axis is stopped (M112, then M999) and the position read back from the device, never assumed.

A firmware counts steps from where it started: after a connect (a board resets when its
USB line opens) or a halt and reset its count says nothing of where the axis is. So a gcode
axis starts unhomed and refuses moves until ``home()`` (there are no end stops: home is
"zero is here", G92 E0); a stop unhomes it again. No target is ever replayed. A step1mm axis
has no reply and no readback: its position is counted, and says so (``measured``).
"""

import math

from tentacle_common.attempts import Attempts
from tentacle_common.errors import DriverError, ExchangeFailed, FrameError, Refused, ReplyTimeout
from tentacle_inserter import gcode, step1mm
from tentacle_inserter.trapezoid import move_time_s, position_at

POLL_S = 0.01  # how often a waiting move looks whether it was cancelled (s)
RESTART_POLL_S = 0.1  # how often a halted firmware is asked whether it is back (s)
STEP1MM_SETTLE_S = 0.02  # a step1mm move is waited for this beyond its expected time (s)


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
        self._motion = None     # (start m, target m, when it began s) of the move under way

    # -- exchanges --------------------------------------------------------------------------
    def _exchange(self, request, timeout_s):
        """Send one line; return the lines before its ``ok`` (raise Refused on Error:)."""
        self.line.write(request)
        deadline = self.line.now() + timeout_s
        lines = []
        while True:
            kind, value = gcode.parse_reply(self.line.read_until(gcode.TERMINATOR, deadline))
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
        motion), the axis is halted (M112, M999) first.
        """
        self.line.open()
        self.attempts.resync()
        if not self._idle():
            self._halt()
        self._command(gcode.absolute())
        self._command(gcode.steps_per_mm(self.steps_per_mm))
        self.homed = False
        return self.read_position()

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
        target = check_target(target_m, self.max_length_m)
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
        self.line.write(gcode.wait_for_motion())
        deadline = self.line.now() + allowed_s
        while not cancelled():
            if self.line.wait_input(min(deadline, self.line.now() + POLL_S)):
                kind, value = gcode.parse_reply(self.line.read_until(gcode.TERMINATOR,
                                                                     deadline))
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
        """Halt at once (M112), reset (M999), read the count back; unhome; return it (m)."""
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
        """
        self.line.write(gcode.halt())   # Marlin answers nothing to M112
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
    cancelled move sends the stop character and counts where the profile had got to.
    """

    measured = False  # no readback: the position is counted

    def __init__(self, line, *, max_length_m, mapping=step1mm.Mapping(), speed_m_s=0.005,
                 accel_m_s2=0.5, start_m=0.0):
        """Bind to a line; the firmware moves at speed_m_s (m/s); count from start_m (m)."""
        self.line, self.max_length_m, self.mapping = line, float(max_length_m), mapping
        self.step_time_s = move_time_s(step1mm.STEP_M, speed_m_s, accel_m_s2)
        self.position_m = float(start_m)
        self._motion = None  # (start m, end m, when it began s, how long it takes s)

    def connect(self):
        """Open the line and stop whatever may be going on."""
        self.line.open()
        self.line.write(self.mapping.command(0))
        return self.position_m

    def home(self):
        """Count from zero here; return 0."""
        self.position_m = 0.0
        return self.position_m

    def move_to(self, target_m, cancelled=lambda: False):
        """
        Send the 1 mm steps towards target_m (whole mm) and wait their expected time.

        :return: the counted position (m)
        :raises TargetRefused: before anything is sent
        :raises MoveStopped: cancelled: the stop character was sent
        """
        target = check_target(target_m, self.max_length_m)
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
        """Send the stop character; return the counted position (what was sent, not done)."""
        self.line.write(self.mapping.command(0))
        return self.position_m
