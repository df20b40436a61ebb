"""
Linear stages behind pseudo-terminals: the inserter's and the backbone's firmware, emulated.

Two device models on pty_device.PtyDevice (pacing, line faults, the received log), with the
codecs of tentacle_inserter so driver and emulator share the wire:

- GcodeStage: Marlin-style (DESIGN.md ``gcode``). Moves are queued and answered ``ok`` at
  once, run one after another with a trapezoidal profile (trapezoid.py) at the commanded
  speed and the firmware's acceleration, to whole motor steps (``M92``); ``M400`` is answered
  when motion has finished (commands sent meanwhile are answered at once: our driver waits
  for each reply, and Marlin would hold them); ``M114`` reports the position; ``M112`` stops
  the axis where it is and answers every later line with Marlin's halted error until
  ``M999`` (which resumes, count and settings kept) or, with ``reset_after_halt_s`` (a
  firmware like Marlin's kill(), which M999 does not bring back), until it restarts by
  itself (it then says ``start`` and counts from 0 where the axis stands, as a rebooted
  board does, with its settings back to their defaults; the axis itself does not move).
- Step1mmStage: the reference rig's inserter (tentacle_inserter.step1mm): each character
  moves 1 mm (or stops), nothing is ever answered.

Faults beyond the line's (``inject``): ``slow`` (moves from now on run at ``factor`` of
their speed; 1 restores it), ``stall`` (the axis stops advancing, after ``after_m`` more
travel, and M400 never answers), ``reset`` (the firmware restarts now), with the line's
``drop_reply`` (a missing ``ok``), ``no_reply`` (a lost line), ``garble``, ``late`` and
``disconnect``. ``state()`` is the truth a test checks the driver against: position
(``position_m`` in the firmware's count, what a driver should report; ``travel_m`` where
the physical axis is, from power-on), velocity, moving, halted.
"""

import threading
import time

from tentacle_common.errors import FrameError
from tentacle_inserter import gcode, step1mm
from tentacle_inserter.trapezoid import move_time_s, position_at
from tentacle_sim.pty_device import PtyDevice


def _check_baud(baud):
    """Raise ValueError unless baud (bit/s) is positive: the line is paced by it."""
    if not baud > 0:
        raise ValueError(f'baud {baud!r}: a line rate must be positive (bit/s)')


class _Axis:
    """The true axis: queued moves run in turn, trapezoidal, to whole steps (SI units)."""

    def __init__(self, accel_m_s2, steps_per_m):
        self.accel, self.steps_per_m = accel_m_s2, steps_per_m
        self.queue = []            # (target m, speed m/s)
        self.move = None           # (start m, target m, speed m/s, t0 s)
        self.rest_m = 0.0          # where it is when not moving
        self.speed_factor = 1.0    # fault 'slow'
        self.stall_at_m = None     # fault 'stall': travel stops here
        self.stalled = False       # stopped at stall_at_m, the move never ending

    def quantise(self, position_m):
        return round(position_m * self.steps_per_m) / self.steps_per_m

    def where(self, now):
        """Return (position m, velocity m/s) now, starting queued moves as the last ends."""
        starts = now  # when the next queued move begins: now, or when the last one ended
        while True:
            if self.stalled:
                return self.rest_m, 0.0
            if self.move is None:
                if not self.queue:
                    return self.rest_m, 0.0
                target, speed = self.queue.pop(0)
                self.move = (self.rest_m, self.quantise(target), speed * self.speed_factor,
                             starts)
            start, target, speed, t0 = self.move
            position, velocity = position_at(now - t0, start, target, speed, self.accel)
            sign = 1.0 if target >= start else -1.0
            if (self.stall_at_m is not None and (self.stall_at_m - start) * sign >= 0
                    and (position - self.stall_at_m) * sign >= 0):
                self.rest_m, self.stalled = self.quantise(self.stall_at_m), True
                return self.rest_m, 0.0
            ends = t0 + move_time_s(target - start, speed, self.accel)
            if now < ends:
                return position, velocity
            self.rest_m, self.move, starts = target, None, ends

    def stop(self, now):
        """Stop where it is (at once: an emergency stop loses the deceleration)."""
        self.rest_m = self.quantise(self.where(now)[0])
        self.move, self.queue, self.stalled, self.stall_at_m = None, [], False, None

    def idle(self, now):
        """Return whether the firmware has no motion left (a stalled move never ends)."""
        self.where(now)
        return self.move is None and not self.queue


class GcodeStage(PtyDevice):
    """A Marlin-style stage firmware on the E axis."""

    FAULT_KINDS = PtyDevice.FAULT_KINDS + ('slow', 'stall', 'reset')

    def __init__(self, name, *, baud=115200, link_path=None, delay_s=0.0005, log_path=None,
                 accel_m_s2=0.5, steps_per_mm=100.0, reset_after_halt_s=None):
        """
        Describe the firmware; ``start()`` opens the pty.

        :param accel_m_s2: the firmware's acceleration (m/s^2)
        :param steps_per_mm: motor steps per mm until ``M92`` changes it
        :param reset_after_halt_s: after M112, restart by itself this long after (s); None:
            stay halted until M999
        :raises ValueError: a baud that is not positive
        """
        _check_baud(baud)
        super().__init__(name, baud=baud, link_path=link_path, delay_s=delay_s,
                         log_path=log_path)
        self.accel_m_s2 = accel_m_s2
        self.reset_after_halt_s = reset_after_halt_s
        self.boot_steps_per_mm = steps_per_mm
        self._state_lock = threading.Lock()
        self.axis = _Axis(accel_m_s2, steps_per_mm * 1e3)  # the physical axis: it stays put
        self._boot(0.0)

    def _boot(self, now):
        """(Re)start: motion stopped, counting from 0 where the axis stands, absolute."""
        self.axis.stop(now)
        self.axis.steps_per_m = self.boot_steps_per_mm * 1e3
        self.origin_m = self.axis.rest_m  # the firmware's 0, on the physical axis (m)
        self.relative = False
        self.motor_on = True
        self.halted_at = None
        self._waiting = False     # an M400 to answer when motion ends
        self._announce = False    # 'start' to say

    # -- faults -----------------------------------------------------------------------------
    def inject(self, kind, count=1, late_s=0.2, duration_s=1.0, match=None, factor=0.5,
               after_m=0.0):
        """
        Arm a fault.

        :param factor: for 'slow', the fraction of the commanded speed moves run at
        :param after_m: for 'stall', how much further the axis travels before it stops (m)
        """
        with self._state_lock:
            if kind == 'slow':
                self.axis.speed_factor = factor
                return
            if kind == 'stall':
                now = time.monotonic()
                position, velocity = self.axis.where(now)
                ahead = 1.0 if velocity >= 0 else -1.0
                self.axis.stall_at_m = position + ahead * after_m
                return
            if kind == 'reset':
                self._boot(time.monotonic())
                self._announce = True
                return
        super().inject(kind, count, late_s, duration_s, match)

    def state(self):
        """Return the truth: position (m), velocity (m/s), moving; busy (motion left), halted."""
        with self._state_lock:
            now = time.monotonic()
            position, velocity = self.axis.where(now)
            return {'name': self.name, 'connected': self.connected,
                    'port': self.port if self.connected or self.link_path else None,
                    'position_m': position - self.origin_m, 'travel_m': position,
                    'velocity_m_s': velocity,
                    'moving': velocity != 0.0, 'busy': not self.axis.idle(now),
                    'stalled': self.axis.stalled, 'halted': self.halted_at is not None,
                    'motor_on': self.motor_on, 'steps_per_mm': self.axis.steps_per_m * 1e-3,
                    'received': len(self.log), 'pending_faults': self.pending_faults()}

    def travel_m(self):
        """Return where the physical axis is now, m (the firmware's zero does not move it)."""
        with self._state_lock:
            return self.axis.where(time.monotonic())[0]

    # -- the firmware -----------------------------------------------------------------------
    def frame(self, buf):
        """Return (what, n): a line to its terminator (a runaway line is dropped)."""
        end = buf.find(gcode.TERMINATOR)
        if end < 0:
            return ('drop', len(buf)) if len(buf) > 256 else ('wait', 0)
        return 'request', end + 1

    def matches(self, request, match):
        """Return whether a fault armed for command ``match`` (e.g. 'G1') applies."""
        return match is None or request.split()[:1] == [match.encode()]

    def garble(self, reply):
        """Return a line of noise."""
        return b'o\xfek\n'

    def poll(self):
        """Say 'start' after a restart; answer a waiting M400 once motion has ended."""
        with self._state_lock:
            now = time.monotonic()
            if (self.halted_at is not None and self.reset_after_halt_s is not None
                    and now - self.halted_at >= self.reset_after_halt_s):
                self._boot(now)
                self._announce = True
            if self._announce:
                self._announce = False
                return gcode.START
            if self._waiting and self.axis.idle(now):
                self._waiting = False
                return gcode.OK
        return None

    def handle(self, request, apply):
        """Return (meaning, reply) of one line."""
        try:
            code, values = gcode.parse_command(request)
        except FrameError as exc:
            return {'error': str(exc)}, gcode.format_error(f'Unknown command: {exc}')
        meaning = {'command': code, **values}
        if not apply:
            return meaning, None
        with self._state_lock:
            now = time.monotonic()
            if code == 'M112':
                self.axis.stop(now)
                self.halted_at, self._waiting = now, False
                return meaning, None  # Marlin halts without an answer
            if self.halted_at is not None:
                if code == 'M999' and self.reset_after_halt_s is None:
                    self.halted_at = None  # running again; the count and settings kept
                    return meaning, gcode.OK
                return meaning, gcode.format_error(gcode.HALTED)
            return meaning, self._execute(code, values, now)

    def _execute(self, code, values, now):
        """Return the reply of a command on a running firmware (the state lock held)."""
        axis = self.axis
        if code in ('G90', 'G91'):
            self.relative = code == 'G91'
        elif code == 'G92':
            if not axis.idle(now):
                return gcode.format_error('G92 while moving')
            self.origin_m = axis.rest_m - values.get('E', 0.0) * 1e-3
        elif code == 'G1':
            if 'E' not in values:
                return gcode.OK  # only a feed rate: nothing moves
            speed = values.get('F', 600.0) / 60.0 * 1e-3
            if not speed > 0:
                return gcode.format_error('feed rate must be positive')
            base = (axis.queue[-1][0] if axis.queue else axis.move[1] if axis.move
                    else axis.rest_m) if self.relative else self.origin_m
            self.motor_on = True  # a move enables the motor again, as Marlin's does
            axis.queue.append((base + values['E'] * 1e-3, speed))
            axis.where(now)  # start it now if idle
        elif code == 'M400':
            if not axis.idle(now):
                self._waiting = True
                return None
        elif code == 'M114':
            return gcode.format_position((axis.where(now)[0] - self.origin_m) * 1e3) + gcode.OK
        elif code == 'M92':
            if 'E' not in values or not values['E'] > 0:
                return gcode.format_error('M92 needs E > 0')
            axis.steps_per_m = values['E'] * 1e3
        elif code == 'M18':
            axis.stop(now)
            self.motor_on = False
        elif code == 'M999':
            pass  # not halted: nothing to reset
        return gcode.OK


class Step1mmStage(PtyDevice):
    """The reference rig's inserter: a character a millimetre, no reply (step1mm.py)."""

    def __init__(self, name, *, baud=step1mm.BAUD, link_path=None, log_path=None,
                 mapping=step1mm.Mapping(), speed_m_s=0.005, accel_m_s2=0.5):
        """
        Describe the firmware; ``start()`` opens the pty.

        :param mapping: the characters it obeys (step1mm.Mapping)
        :param speed_m_s: how fast each 1 mm move runs (m/s)
        :raises ValueError: a baud that is not positive
        """
        _check_baud(baud)
        super().__init__(name, baud=baud, link_path=link_path, delay_s=0.0, log_path=log_path)
        self.mapping, self.speed_m_s = mapping, speed_m_s
        self.axis = _Axis(accel_m_s2, 1e6)
        self._state_lock = threading.Lock()

    def answered(self, request):
        """Return False: step1mm firmware answers nothing."""
        return False

    def frame(self, buf):
        """Return ('request', 1): every byte is a command."""
        return 'request', 1

    def handle(self, request, apply):
        """Queue a 1 mm move or stop; answer nothing."""
        try:
            direction = self.mapping.parse(request)
        except FrameError as exc:
            return {'error': str(exc)}, None
        meaning = {'command': {1: 'extend', -1: 'retract', 0: 'stop'}[direction]}
        if apply:
            with self._state_lock:
                now = time.monotonic()
                if direction == 0:
                    self.axis.stop(now)
                else:
                    last = (self.axis.queue[-1][0] if self.axis.queue else self.axis.move[1]
                            if self.axis.move else self.axis.rest_m)
                    self.axis.queue.append((last + direction * step1mm.STEP_M, self.speed_m_s))
                    self.axis.where(now)
        return meaning, None

    def state(self):
        """Return the truth: position (m), velocity (m/s), moving."""
        with self._state_lock:
            now = time.monotonic()
            position, velocity = self.axis.where(now)
            return {'name': self.name, 'connected': self.connected, 'position_m': position,
                    'velocity_m_s': velocity, 'moving': velocity != 0.0,
                    'busy': not self.axis.idle(now), 'received': len(self.log)}
