"""
One axis driven from a thread of its own: the latest target, with stop and estop first.

The node (inserter_node) and lab scripts reach an axis through this. ``set_target`` checks a
target at once (TargetRefused, nothing sent) and hands it to the worker, which moves to the
latest only: a target that arrives while the axis moves replaces any not yet started, and
none is replayed after a fault or a reconnect: while the line is down targets are refused,
and a connect drops any pending one. ``stop`` and ``set_estop(True)`` cut a move short at
once (the driver's cancelled poll: M112, then M999); while the estop holds no target is
taken. A lost line is reopened every ``reconnect_s`` and the axis comes back unhomed, its
position read back, never assumed; a device that never answered (stage.NeverAnswered) is
not tried again (``gave_up``). ``snapshot()`` is what /<axis>/state and /diagnostics publish.
"""

import logging
import threading

from tentacle_common.errors import DriverError, LinkLost
from tentacle_inserter.stage import MoveStopped, NeverAnswered, TargetRefused

HOME_TIMEOUT_S = 10.0
log = logging.getLogger('tentacle_inserter')


class AxisWorker:
    """A stage driver (stage.GcodeStage or Step1mmStage) owned by one thread."""

    def __init__(self, stage, *, reconnect_s=1.0):
        """Take a driver not yet connected; ``start()`` runs the thread."""
        self.stage, self.reconnect_s = stage, float(reconnect_s)
        self._cond = threading.Condition()
        self._target = None         # the latest target not yet started, m
        self._stop = False          # a stop asked for and not yet done
        self._home = None           # a threading.Event while a home is asked for
        self._home_result = (False, '')
        self._estop = False
        self._enabled = True
        self._motor_off = False     # a disable asked for and not yet done
        self._shutdown = False
        self._moving = False
        self.connected = False      # changed under _cond, with the pending target
        self.gave_up = ''           # why connecting stopped for good ('' while it goes on)
        self.error = ''             # the last fault, '' after a good move
        self.moves = self.refusals = 0
        self.stop_sent = False      # the stop at shutdown went to the stage
        self.stopped = False        # the stop at shutdown was answered by the stage
        self._thread = threading.Thread(target=self._run, name='axis-worker', daemon=True)

    # -- what callers do --------------------------------------------------------------------
    def start(self):
        """Start the worker (it connects, then waits for work)."""
        self._thread.start()
        return self

    def set_target(self, target_m):
        """
        Hand a target (m) to the worker; it replaces any not yet started.

        :raises TargetRefused: not a target the stage takes (stage.check), the estop holds,
            disabled, not connected or not homed (nothing sent, nothing kept)
        """
        try:
            target = self.stage.check(target_m)
            with self._cond:
                if self._estop:
                    raise TargetRefused('estop active: no motion until it is released')
                if not self._enabled:
                    raise TargetRefused('axis disabled: enable it first')
                if not self.connected:  # kept, it would be replayed after the reconnect
                    raise TargetRefused('not connected: ' + (self.error or 'the line is down')
                                        + ' (a target is not kept for when it is back)')
                if not self.stage.homed:
                    raise TargetRefused('not homed (after a connect or a stop): home it first')
                self._target = target
                self._cond.notify_all()
        except TargetRefused:
            self.refusals += 1
            raise

    def stop(self):
        """Stop now: drop the pending target and cut the move short."""
        with self._cond:
            self._target, self._stop = None, True
            self._cond.notify_all()

    def set_estop(self, active):
        """Engage (stop, and refuse targets until released) or release the estop."""
        with self._cond:
            self._estop = bool(active)
            if self._estop:
                self._target, self._stop = None, True
            self._cond.notify_all()

    def set_enabled(self, on):
        """Enable (targets taken again) or disable (stop, motor off, targets refused)."""
        with self._cond:
            self._enabled = bool(on)
            if not on:
                self._target, self._stop, self._motor_off = None, True, True
            self._cond.notify_all()

    def home(self, timeout_s=HOME_TIMEOUT_S):
        """Make where the axis stands its zero; return (success, message)."""
        with self._cond:
            if self._estop:
                return False, 'estop active'
            done = self._home = threading.Event()
            self._cond.notify_all()
        if not done.wait(timeout_s):
            return False, f'no answer in {timeout_s:g} s'
        return self._home_result

    def snapshot(self):
        """
        Return the state to publish: position (m), velocity (m/s), moving, homed, faults.

        During a move the position and velocity are the move's profile (the firmware is
        busy with it), and ``estimated`` says so; a step1mm position is always estimated.
        """
        position, velocity, measured = self.stage.estimate()
        with self._cond:
            return {'position_m': position, 'velocity_m_s': velocity,
                    'estimated': not measured, 'moving': self._moving,
                    'homed': getattr(self.stage, 'homed', True), 'connected': self.connected,
                    'measured': self.stage.measured, 'estop': self._estop,
                    'enabled': self._enabled,
                    'error': self.error, 'moves': self.moves, 'refusals': self.refusals}

    def idle(self):
        """Return True when no target waits and no move, stop or home runs."""
        with self._cond:
            return (self._target is None and not self._moving and not self._stop
                    and self._home is None)

    def status(self):
        """Return (level 'ok' | 'warn' | 'error', message) for /diagnostics."""
        snap = self.snapshot()
        if not snap['connected']:
            return 'error', snap['error'] or 'not connected'
        if snap['estop']:
            return 'warn', 'estop active: stopped'
        if not snap['enabled']:
            return 'warn', 'disabled: motor off, targets refused'
        if not snap['homed']:
            return 'warn', 'not homed: call home before moving'
        if snap['error']:
            return 'warn', snap['error']
        return 'ok', 'moving' if snap['moving'] else 'ready'

    def shutdown(self, timeout_s=5.0):
        """Stop the axis, close the line, end the thread; return whether the stop was answered."""
        with self._cond:
            self._shutdown, self._target, self._stop = True, None, True
            self._cond.notify_all()
        self._thread.join(timeout_s)
        return self.stopped

    # -- the thread -------------------------------------------------------------------------
    def _cancelled(self):
        with self._cond:
            return self._stop or self._shutdown

    def _run(self):
        while True:
            with self._cond:
                if self._shutdown:
                    break
            self._step()
        self._close()

    def _step(self, wait_s=0.5):
        """Do one turn of the thread: connect, or wait up to wait_s (s) for work and do it."""
        if self.gave_up:  # nothing more is sent to a device that never answered
            with self._cond:
                self._cond.wait_for(lambda: self._shutdown or self._home, timeout=wait_s)
                home, self._home = self._home, None
                self._target, self._stop, self._motor_off = None, False, False
            if home is not None:
                self._home_result = (False, self.error)
                home.set()
            return
        if not self.connected:
            self._connect()
            return
        with self._cond:
            self._cond.wait_for(lambda: self._shutdown or self._stop or self._home
                                or self._target is not None, timeout=wait_s)
            stop, home, target = self._stop, self._home, self._target
            motor_off = self._motor_off
            self._stop, self._home, self._target, self._motor_off = False, None, None, False
            self._moving = target is not None and not stop
        try:
            if stop:
                self.stage.stop()
            if motor_off:
                self.stage.motor_off()
            if home is not None:  # a home asked for with (or after) a stop still happens
                self.stage.home()
                self._home_result, self.error = (True, 'zero is here'), ''
                home.set()
            elif target is not None:
                self.stage.move_to(target, cancelled=self._cancelled)
                self.moves += 1
                self.error = ''
        except MoveStopped as exc:
            self.error = str(exc)
            log.warning('%s', exc)
            with self._cond:
                self._stop = False  # the stop that cut the move short is done
        except LinkLost as exc:
            self._lost(exc, home)
        except DriverError as exc:
            self.error = str(exc)
            log.error('%s', exc)
            if home is not None:
                self._home_result = (False, str(exc))
                home.set()
        finally:
            with self._cond:
                self._moving = False

    def _connect(self):
        try:
            position = self.stage.connect()
            with self._cond:
                # Anything pending was asked of the axis before this connect: never replayed.
                self._target = None
                self.connected, self.error = True, ''
            log.info('connected: axis stopped at %.3f mm (%s)', position * 1e3,
                     'read back; home it before moving' if self.stage.measured else 'counted')
        except NeverAnswered as exc:
            self.error = self.gave_up = f'connect: {exc}'
            log.error('%s; not tried again: check the dialect and baud, then restart',
                      self.error)
            self.stage.line.close()
        except (LinkLost, DriverError) as exc:
            self.error = f'connect: {exc}'
            self.stage.line.close()
            with self._cond:
                self._cond.wait_for(lambda: self._shutdown, timeout=self.reconnect_s)

    def _lost(self, exc, home):
        with self._cond:
            self.connected, self.error = False, f'line lost: {exc}'
            self._target = None  # a target from before the loss is never replayed
        log.error('%s: reconnecting every %g s; the axis comes back stopped and unhomed',
                  self.error, self.reconnect_s)
        self.stage.line.close()
        if home is not None:
            self._home_result = (False, self.error)
            home.set()

    def _close(self):
        if self.connected:  # a device that never answered is sent nothing, not even a stop
            try:
                self.stage.stop()
                self.stop_sent = True
                self.stopped = self.stage.measured  # a step1mm stop is sent, never confirmed
            except (LinkLost, NeverAnswered) as exc:
                self.error = f'stop at shutdown: {exc}'
            except DriverError as exc:  # it went out; what came back was not a confirmation
                self.stop_sent = True
                self.error = f'stop at shutdown: {exc}'
        self.stage.line.close()
