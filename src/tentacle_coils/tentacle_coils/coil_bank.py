"""
Three supplies driven as one coil bank: limits, slew, watchdog, faults and safe stop.

Each axis is a Channel: its own serial line and one worker thread, so the three supplies are
commanded in parallel and each waits only for its own ACK. Commands are latest-wins: a
worker always sends the newest target, never a queue of stale ones. Measured currents are
read right after a set (when due), so a read never delays the next command in a steady
stream. A supervisor thread runs the watchdog and finishes safe stops.

Safety rules, in one place:
- A command is validated before it touches a target; a rejected one never reaches a wire.
- Any supply fault (retries exhausted, link lost) drives every axis to zero and refuses
  commands until all supplies are connected again and hold zero; a reconnected supply is
  driven to zero, never back to its stale setpoint.
- One safe stop (``_begin_stop``): ramp to zero at the slew limit, then outputs off. Estop
  and disable use it; ``shutdown()`` uses it and waits for the supplies to confirm before
  it stops the workers. The watchdog ramps to zero and leaves outputs on.
- A set is decided under its channel's lock right before it is written, and every zeroing
  request (fault, estop, stop, watchdog) makes sets planned before it stale: a worker that
  was busy on the line when the request came, or is retrying an unanswered set, never sends
  a value from before it (a stale retry reads back what the device holds and ramps from there).
- Nothing is logged while the bank's lock is held: a log line ends in the node's pipe, and a
  stalled reader must never hold up a stop.
"""

import contextlib
import logging
import math
import threading
import time

import numpy as np

from tentacle_coils.errors import (CommandRejected, ConfigError, LinkLost, Superseded,
                                   SupplyFault)
from tentacle_coils.supply import make_supply
from tentacle_common.serial_line import SerialLine

log = logging.getLogger('tentacle_coils')

STEP_DT_CAP_S = 0.05  # longest interval one slew step may cover (s)
READBACK_MAX_DEFER_S = 0.5  # longest a readback waits for a busy command stream (s)
STOP_GRACE_S = 1.0  # a safe stop switches outputs off this long after the ramp at the latest


class Channel:
    """One axis: a Supply on its SerialLine, served by one worker thread."""

    def __init__(self, name, supply, *, slew_rate_a_per_s, readback_period_s,
                 backoff_s=(0.1, 2.0), on_fault=None):
        """
        Bind an axis to its supply.

        :param name: axis label, 'x', 'y' or 'z'
        :param supply: a Supply whose line is not yet open
        :param slew_rate_a_per_s: largest rate of change of the setpoint (A/s)
        :param readback_period_s: how often to read the measured current (s)
        :param backoff_s: (first, longest) wait between reconnect attempts (s)
        :param on_fault: called with (channel, reason) from the worker on a fault
        """
        self.name = name
        self.supply = supply
        self.slew_rate_a_per_s = float(slew_rate_a_per_s)
        self.readback_period_s = float(readback_period_s)
        self.backoff_s = backoff_s
        self.on_fault = on_fault or (lambda channel, reason: None)
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f'coil-{name}', daemon=True)
        self.target_a = 0.0
        self.sent_a = 0.0  # the setpoint the device holds, as far as the driver knows (A)
        self.output_wanted = False
        self.output_on = None  # None: unknown (before connect)
        self.confirmed = False  # a read-back since the last set agreed with sent_a, output_on
        self.held = None  # (setpoint A, output on) as last read back from the device
        self.measured_a = math.nan
        self.measured_at_s = math.nan  # wall clock (time.time()) the reading was asked at
        self.connected = False
        self.last_error = ''
        self.updates = 0
        self.faults = 0
        self._unreachable_logged = False
        self._force_off = False
        self._generation = 0  # bumped by every zeroing request: sets planned before are stale
        # Line-clock times (supply.line.now()): the slew reference is when the previous set
        # left the line, or when the target left rest, whichever is later.
        self._t_ref = -math.inf
        self._t_last_set = -math.inf
        self._next_readback = 0.0
        self._next_verify = 0.0

    @property
    def label(self):
        """Return 'axis (port)' for messages."""
        return f'{self.name} ({self.supply.line.path})'

    # -- called from other threads ----------------------------------------------------------
    def request(self, target_a=None, output=None, force_off=False):
        """
        Set the target current (A) and/or the wanted output state; returns at once.

        An output is switched off once its current is at zero, unless ``force_off``.
        """
        with self._cond:
            if target_a is not None:
                if self.target_a == self.sent_a:
                    # Leaving rest: the slew budget starts now, or when the last set leaves
                    # the line if it is still on its way.
                    self._t_ref = max(self.supply.line.now(), self._t_ref)
                self.target_a = float(target_a)
            if output is not None:
                self.output_wanted = bool(output)
                self._force_off = force_off
            self._cond.notify()

    def zero(self):
        """Drive the target to zero; a set planned or retried from before this is dropped."""
        with self._cond:
            self._generation += 1
            self.request(target_a=0.0)

    def settled_zero(self):
        """Return True when a read-back confirmed a zero setpoint (or it is unreachable)."""
        with self._cond:
            return not self.connected or self._zero_confirmed()

    def settled_off(self):
        """Return True when a read-back confirmed zero and off (or it is unreachable)."""
        with self._cond:
            return not self.connected or (self._zero_confirmed() and self.output_on is False
                                          and not self.output_wanted)

    def _zero_confirmed(self):
        return self.confirmed and self.sent_a == 0.0 and self.target_a == 0.0

    def unsafe_reason(self):
        """Return '' when the device read back zero current and output off, else why not."""
        with self._cond:
            if not self.connected:
                return f'{self.label}: not connected ({self.last_error or "never answered"})'
            if not self.confirmed:
                held = '' if self.held is None else (
                    f': last read back {self.held[0]:.4f} A, output '
                    f'{"on" if self.held[1] else "off"}')
                return f'{self.label}: zero and off not confirmed by read-back{held}'
            if self.sent_a != 0.0:
                return f'{self.label}: holds {self.sent_a:.4f} A'
            if self.output_on:
                return f'{self.label}: output on'
            return ''

    def snapshot(self):
        """Return the channel's state as a dict (for diagnostics)."""
        with self._cond:
            return {
                'axis': self.name, 'port': self.supply.line.path,
                'address': self.supply.address, 'dialect': self.supply.dialect,
                'identity': self.supply.identity, 'connected': self.connected,
                'output_on': bool(self.output_on), 'target_a': self.target_a,
                'setpoint_a': self.sent_a, 'measured_a': self.measured_a,
                'confirmed': self.confirmed, 'last_error': self.last_error,
                'updates': self.updates, 'faults': self.faults, **self.supply.counters,
            }

    def start(self):
        """Start the worker (it connects, with backoff)."""
        self._thread.start()

    def stop(self):
        """Stop the worker and close the line."""
        self._stop.set()
        with self._cond:
            self._cond.notify()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self.supply.line.close()

    # -- worker -----------------------------------------------------------------------------
    def _run(self):
        backoff = self.backoff_s[0]
        while not self._stop.is_set():
            if not self.connected:
                if self._connect():
                    backoff = self.backoff_s[0]
                else:
                    self._stop.wait(backoff)
                    backoff = min(2 * backoff, self.backoff_s[1])
                continue
            try:
                self._serve()
            except LinkLost as exc:
                with self._cond:
                    self.connected = False
                    self.confirmed = False
                    self.measured_a = math.nan
                self._fault(f'link lost: {exc}')
                self.supply.line.close()
            except SupplyFault as exc:
                with self._cond:
                    self.confirmed = False
                self._fault(str(exc))
                self._stop.wait(self.backoff_s[0])

    def _fault(self, reason):
        with self._cond:
            self.last_error = reason
            self.faults += 1
        self.on_fault(self, reason)

    def _connect(self):
        try:
            self.supply.line.open()
            identity = self.supply.connect()
            held_a, output_on = self.supply.read_held()
        except (LinkLost, SupplyFault) as exc:
            self.supply.line.close()
            with self._cond:
                self.last_error = f'connect: {exc}'
            if not self._unreachable_logged:  # once per outage; diagnostics carry the rest
                self._unreachable_logged = True
                log.error('supply %s unreachable (retrying with backoff): %s', self.label, exc)
            return False
        self._unreachable_logged = False
        with self._cond:
            self.connected = True
            # Go on from what the device holds (a reconnected supply may still carry its
            # old current): targets are zero after a fault, so it ramps down from there.
            self.sent_a, self.output_on = held_a, output_on
            self.held = (held_a, output_on)
            self.confirmed = False
            self._t_ref = self.supply.line.now()
            self._next_readback = self._next_verify = 0.0
        log.info('supply %s connected: %s', self.label, identity)
        return True

    def _output_due(self):
        """Return whether the output should switch now: on at once, off at zero current."""
        return self.output_on != self.output_wanted and (
            self.output_wanted or self.sent_a == 0.0 or self._force_off)

    def _due_in(self, now):
        """Return seconds until there is work (<= 0: now); call with the lock held."""
        if self.target_a != self.sent_a or self._output_due():
            return 0.0
        if self.target_a == 0.0 and not self.confirmed:
            return 0.0  # a safe state is confirmed by read-back as soon as it is reached
        wake = max(self._next_readback, self._t_last_set + self.readback_period_s)
        if self.supply.verify_period_s is not None:
            wake = min(wake, self._next_verify)
        return wake - now

    def _serve(self):
        """
        Do what is due: output change, one slew step, a readback, a read-back check.

        A readback goes right after a set when one is due and no newer command is waiting,
        so in a command stream it uses the line while it would idle until the next command;
        when commands keep the line busy it is deferred, for at most READBACK_MAX_DEFER_S.
        It runs on its own only when no set has gone out for a readback period: a command
        never waits behind a readback while commands keep coming. The held state is read
        back on the supply's own verify period (whatever the readback rate), and at once
        when zero current is reached.
        """
        line = self.supply.line
        with self._cond:
            while not self._stop.is_set():
                wait = self._due_in(line.now())
                if wait <= 0:
                    break
                self._cond.wait(wait)
            wanted, switch = self.output_wanted, self._output_due()
        if self._stop.is_set():
            return
        if switch:
            self.supply.set_output(wanted)
            with self._cond:
                self.output_on = wanted
                self.confirmed = False
        self._step()  # planned now, not before the switch: the target may have changed since
        now = line.now()
        with self._cond:
            busy = self.target_a != self.sent_a
            verify = (self.target_a == 0.0 and not self.confirmed and not busy) or (
                self.supply.verify_period_s is not None and now >= self._next_verify)
        if now >= self._next_readback + (READBACK_MAX_DEFER_S if busy else 0.0):
            self._next_readback = now + self.readback_period_s
            # Stamped when asked: the device measured after this, so an age taken from it
            # is never less than the reading's true age.
            asked_at = time.time()
            measured = self.supply.read_current()
            with self._cond:
                self.measured_a, self.measured_at_s = measured, asked_at
        if verify:
            self._verify()

    def _step(self):
        """Send one slew-limited step towards the target, decided under the lock (A)."""
        line = self.supply.line
        with self._cond:
            if self.target_a == self.sent_a:
                return
            now = line.now()
            # The step's own bytes leave no earlier than now plus their wire time, and the
            # previous set left at _t_ref: that interval bounds the change at the device.
            interval = max(now - self._t_ref, 0.0) + line.wire_time_s(self.supply.set_bytes)
            max_step = self.slew_rate_a_per_s * min(interval, STEP_DT_CAP_S)
            delta = self.target_a - self.sent_a
            setpoint = self.target_a if abs(delta) <= max_step else self.sent_a + math.copysign(
                max_step, delta)
            if setpoint * self.sent_a < 0.0:
                setpoint = 0.0  # stop at zero on the way through: polarity changes at rest only
            generation = self._generation

        def still_wanted():  # asked right before each write of this set, retries included
            with self._cond:
                return self._generation == generation

        try:
            self.supply.set_current(setpoint, still_wanted)
        except Superseded as exc:
            if exc.ambiguous:  # an unanswered attempt may have landed: plan from the device
                self._go_on_from_device()
            return
        self._t_ref = line.tx_free_at
        self._t_last_set = now
        with self._cond:
            self.sent_a = setpoint
            self.confirmed = False
            self.updates += 1

    def _go_on_from_device(self):
        """Read back what the device holds and take it as the slew's starting point."""
        held_a, output_on = self.supply.read_held()
        with self._cond:
            self.sent_a, self.output_on = held_a, output_on
            self.held = (held_a, output_on)
            self.confirmed = False
            self._t_ref = self.supply.line.now()

    def _verify(self):
        """Read back what the device holds; where it differs, go on from what it holds."""
        setpoint_a, output_on = self.supply.read_held()
        errors = self.supply.errors()
        self._next_verify = self.supply.line.now() + (self.supply.verify_period_s or 0.0)
        with self._cond:
            self.held = (setpoint_a, output_on)
            problems = list(errors)
            if abs(setpoint_a - self.sent_a) > self.supply.resolution_a / 2 + 1e-9:
                problems.append(f'device holds {setpoint_a:.4f} A, not {self.sent_a:.4f} A')
                self.sent_a = setpoint_a  # the slew limit applies from what it really holds
            if output_on != self.output_on:
                problems.append(f'output is {"on" if output_on else "off"}, not '
                                f'{"on" if self.output_on else "off"}')
                self.output_on = output_on
            self.confirmed = len(problems) == len(errors)
            text, repeated = '; '.join(problems), '; '.join(problems) == self.last_error
            if problems:
                self.last_error = text
        if problems and not repeated:  # a device that keeps disagreeing is logged once
            log.warning('supply %s reports %s; setpoint re-sent', self.label, text)
            if self.confirmed:  # device errors only: the held state is right, assert it again
                self.supply.set_current(self.sent_a)
                self._t_ref = self.supply.line.tx_free_at


class CoilBank:
    """Three channels (x, y, z) with command validation, watchdog and safe stop."""

    def __init__(self, channels, *, max_current_a, watchdog_s, supervise_period_s=0.02):
        """
        Take ownership of the channels.

        :param channels: three Channels in x, y, z order
        :param max_current_a: largest current magnitude any command may ask for (A)
        :param watchdog_s: with outputs on, ramp to zero after this long without a command (s)
        """
        self.channels = list(channels)
        for channel in self.channels:
            channel.on_fault = self._on_fault
        self.max_current_a = float(max_current_a)
        self.watchdog_s = float(watchdog_s)
        self.supervise_period_s = supervise_period_s
        self._lock = threading.Lock()
        self._enabled = False
        self._estop = False
        self._was_enabled = False  # outputs on when the estop came: restored on release
        self._fault = ''
        self._stopping = ''   # reason of a safe stop in progress (ramp, then outputs off)
        self._stop_deadline = 0.0
        self._watchdog_tripped = False
        self._last_command = time.monotonic()
        self.unsafe = []  # after shutdown(): what could not be confirmed zero and off
        self._halt = threading.Event()
        self._supervisor = threading.Thread(target=self._supervise, name='coil-supervisor',
                                            daemon=True)

    # -- state ------------------------------------------------------------------------------
    @property
    def enabled(self):
        """Return True while outputs are meant to be on."""
        return self._enabled

    @property
    def estopped(self):
        """Return True while an emergency stop is active."""
        return self._estop

    @property
    def fault(self):
        """Return the reason of the active fault, or '' when there is none."""
        return self._fault

    def connected(self):
        """Return True when every supply is connected."""
        return all(ch.connected for ch in self.channels)

    def measured_currents(self):
        """Return the measured currents (3,) in A; NaN where unknown."""
        return np.array([ch.measured_a for ch in self.channels])

    def measured_at(self):
        """Return the wall-clock time (s, time.time()) of the oldest reading; NaN if unknown."""
        times = [ch.measured_at_s for ch in self.channels]
        return math.nan if any(math.isnan(t) for t in times) else min(times)

    def setpoints(self):
        """Return the setpoints the supplies hold (3,) in A."""
        return np.array([ch.sent_a for ch in self.channels])

    def snapshots(self):
        """Return one dict per supply (for diagnostics)."""
        return [ch.snapshot() for ch in self.channels]

    def status(self):
        """Return (level, message) for the bank: 'ok', 'warn' or 'error'."""
        if self._estop:
            unsafe = [r for r in (ch.unsafe_reason() for ch in self.channels) if r]
            if unsafe:
                return 'warn', 'estop active: going to zero and off, not yet confirmed: ' + (
                    '; '.join(unsafe))
            return 'warn', 'estop active: outputs zero and off (read back)'
        if self._fault:
            return 'error', f'fault: {self._fault}'
        if not self.connected():
            return 'error', 'not every supply is connected'
        if self._watchdog_tripped:
            return 'warn', f'watchdog: no command for {self.watchdog_s:g} s, ramped to zero'
        return 'ok', 'enabled' if self._enabled else 'disabled (outputs off)'

    # -- commands ---------------------------------------------------------------------------
    def start(self):
        """Start the channel workers and the supervisor."""
        for channel in self.channels:
            channel.start()
        self._supervisor.start()

    def command(self, currents_a):
        """
        Set new target currents (3,) in A.

        :raises CommandRejected: not finite, over max_current, estop, disabled or faulted
        """
        currents = np.asarray(currents_a, dtype=float).reshape(-1)
        if currents.size != 3 or not np.all(np.isfinite(currents)):
            raise CommandRejected(f'currents {currents.tolist()} A are not three finite numbers')
        if np.max(np.abs(currents)) > self.max_current_a:
            raise CommandRejected(f'currents {np.round(currents, 4).tolist()} A exceed '
                                  f'max_current {self.max_current_a:g} A')
        with self._lock:
            if self._estop:
                raise CommandRejected('estop active')
            if self._fault:
                raise CommandRejected(f'supply fault: {self._fault}')
            if not self._enabled:
                raise CommandRejected('outputs disabled: call /coils/enable first')
            self._last_command = time.monotonic()
            self._watchdog_tripped = False
            for channel, current_a in zip(self.channels, currents):
                channel.request(target_a=current_a)

    def enable(self, on):
        """
        Energise (outputs on, zero current) or de-energise (ramp to zero, outputs off).

        :return: (success, message)
        """
        if not on:
            self._safe_stop('disabled')
            return True, 'ramping to zero, then outputs off'
        with self._lock:
            if self._estop:
                return False, 'estop active'
            if self._fault:
                return False, f'supply fault: {self._fault}'
            missing = [ch.name for ch in self.channels if not ch.connected]
            if missing:
                return False, f'supply {", ".join(missing)} not connected'
            self._enabled = True
            self._stopping = ''
            self._last_command = time.monotonic()
            for channel in self.channels:
                channel.request(target_a=0.0, output=True)
            return True, 'outputs on at zero current'

    def set_estop(self, active):
        """
        Engage or release the emergency stop.

        Engaging ramps to zero and switches outputs off. Releasing restores the outputs that
        were on before, at zero current: nothing moves until a new command.
        """
        with self._lock:
            if active == self._estop:
                return
            self._estop = active
            if active:
                self._was_enabled = self._enabled
                self._begin_stop('estop')
        if active:  # a warning: never dropped on its way to the node
            log.warning('coils: safe stop (estop)')
        elif self._was_enabled:
            self.enable(True)

    def _ramp_time_s(self):
        """Return how long the slowest axis takes to ramp to zero at the slew limit (s)."""
        return max(abs(ch.sent_a) / ch.slew_rate_a_per_s for ch in self.channels)

    def _begin_stop(self, reason):
        """
        Zero every target now; the supervisor switches outputs off once all read back zero.

        Off is safer than on at any current: if some supply cannot confirm zero within the
        ramp time plus STOP_GRACE_S, every output is switched off all the same. Call with the
        lock held; log after releasing it.
        """
        self._enabled = False
        self._stopping = reason
        self._stop_deadline = time.monotonic() + self._ramp_time_s() + STOP_GRACE_S
        for channel in self.channels:
            channel.zero()

    def _safe_stop(self, reason):
        with self._lock:
            self._begin_stop(reason)
        log.info('coils: safe stop (%s)', reason)

    def _on_fault(self, channel, reason):
        with self._lock:
            first = not self._fault
            self._fault = f'{channel.name}: {reason}'
            for ch in self.channels:
                ch.zero()
        if first:
            log.error('coils: supply %s fault, all axes to zero: %s', channel.name, reason)

    def _supervise(self):
        while not self._halt.wait(self.supervise_period_s):
            self.supervise_once()

    def supervise_once(self):
        """Run the watchdog, finish a safe stop, clear a fault that has gone (one pass)."""
        tripped, cleared = False, ''
        with self._lock:
            now = time.monotonic()
            if (self._enabled and not self._watchdog_tripped
                    and now - self._last_command > self.watchdog_s
                    and any(ch.target_a != 0.0 for ch in self.channels)):
                self._watchdog_tripped = True
                for channel in self.channels:
                    channel.zero()
                tripped = True
            late = now > self._stop_deadline
            if self._stopping and (late or all(ch.settled_zero() for ch in self.channels)):
                for channel in self.channels:
                    channel.request(output=False, force_off=late)
                self._stopping = ''
            if self._fault and self._all_connected_at_zero():
                cleared, self._fault = self._fault, ''
        if tripped:
            log.warning('coils: watchdog, no command for %.3g s: ramping to zero',
                        self.watchdog_s)
        if cleared:
            log.info('coils: fault cleared (%s); every supply read back zero', cleared)

    def _all_connected_at_zero(self):
        """
        Return True when every supply is connected and read back zero, at one instant.

        Every channel's lock is held for the look (bank lock, then channels, as everywhere):
        a supply that drops between two looks must not let a fault clear.
        """
        with contextlib.ExitStack() as held:
            for channel in self.channels:
                held.enter_context(channel._cond)
            return all(ch.connected and ch._zero_confirmed() for ch in self.channels)

    def shutdown(self, reason='shutdown', timeout_s=None):
        """
        Ramp to zero, switch outputs off and stop every worker; blocks until done.

        Zero and off count only when read back from each device; a worker that reads back
        anything else goes on from what the device holds until the deadline. What could not
        be confirmed is left in ``unsafe``, one line per supply.

        :param timeout_s: how long to wait for the ramp (s); default: the ramp time at the
            slew limit plus one second; switching off and confirming get one second more
        :return: True when every supply read back zero current and output off
        """
        self._safe_stop(reason)
        if timeout_s is None:
            timeout_s = self._ramp_time_s() + STOP_GRACE_S
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not all(
                ch.settled_zero() for ch in self.channels):
            time.sleep(0.005)
        for channel in self.channels:
            channel.request(output=False, force_off=True)  # off is safer than on at any current
        while time.monotonic() < deadline + 1.0 and not all(
                ch.settled_off() for ch in self.channels):
            time.sleep(0.005)
        self.unsafe = [r for r in (ch.unsafe_reason() for ch in self.channels) if r]
        self._halt.set()
        if self._supervisor.is_alive():
            self._supervisor.join(timeout=1.0)
        for channel in self.channels:
            channel.stop()
        return not self.unsafe


def build_bank(ports, *, dialect, baud, addresses=(1, 1, 1), polarity_inverted=(False,) * 3,
               polarity_mode='signed', max_current_a, slew_rate_a_per_s, watchdog_s,
               readback_period_s=0.1, retries=3, reply_timeout_s=0.1, max_turnaround_s=0.25,
               voltage_limit_v=30.0):
    """
    Return a CoilBank of three supplies on the given ports (x, y, z), not yet started.

    :raises ConfigError: wrong counts, an unknown dialect or polarity mode
    """
    for what, values in (('ports', ports), ('addresses', addresses),
                         ('polarity_inverted', polarity_inverted)):
        if len(values) != 3:
            raise ConfigError(f'{what} needs 3 entries (x, y, z), got {len(values)}')
    if not all(0 <= a <= 255 for a in addresses):
        raise ConfigError(f'addresses {list(addresses)} must each be in 0..255')
    for i, j in ((0, 1), (0, 2), (1, 2)):
        if ports[i] == ports[j]:  # each supply needs a line of its own: the second cannot open
            log.error('ports: supplies %s and %s both name %s; each needs its own port',
                      'xyz'[i], 'xyz'[j], ports[i])
    channels = []
    for name, port, address, inverted in zip('xyz', ports, addresses, polarity_inverted):
        supply = make_supply(dialect, SerialLine(port, baud), address=address,
                             polarity_inverted=inverted, polarity_mode=polarity_mode,
                             retries=retries, reply_timeout_s=reply_timeout_s,
                             max_turnaround_s=max_turnaround_s, voltage_limit_v=voltage_limit_v)
        channels.append(Channel(name, supply, slew_rate_a_per_s=slew_rate_a_per_s,
                                readback_period_s=readback_period_s))
    return CoilBank(channels, max_current_a=max_current_a, watchdog_s=watchdog_s)
