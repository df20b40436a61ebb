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
"""

import logging
import math
import threading
import time

import numpy as np

from tentacle_coils.errors import CommandRejected, ConfigError, LinkLost, SupplyFault
from tentacle_coils.supply import make_supply
from tentacle_coils.transport import SerialLine

log = logging.getLogger('tentacle_coils')

STEP_DT_CAP_S = 0.05  # longest interval one slew step may cover (s)
READBACK_MAX_DEFER_S = 0.5  # longest a readback waits for a busy command stream (s)
CHECK_PERIOD_S = 1.0  # how often to ask a supply for errors it would not report itself (s)


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
        self.sent_a = 0.0
        self.output_wanted = False
        self.output_on = None  # None: unknown (before connect)
        self.measured_a = math.nan
        self.connected = False
        self.last_error = ''
        self.updates = 0
        self.faults = 0
        self._t_step = time.monotonic()  # start of the current slew step (s)
        self._t_last_set = 0.0
        self._next_readback = 0.0
        self._next_check = 0.0

    # -- called from other threads ----------------------------------------------------------
    def request(self, target_a=None, output=None):
        """Set the target current (A) and/or the wanted output state; returns at once."""
        with self._cond:
            if target_a is not None:
                if self.target_a == self.sent_a:
                    # Leaving rest: the slew budget starts now, not at the last send.
                    self._t_step = time.monotonic()
                self.target_a = float(target_a)
            if output is not None:
                self.output_wanted = bool(output)
            self._cond.notify()

    def at_zero(self):
        """Return True when the device confirmed a zero setpoint (or is unreachable)."""
        with self._cond:
            return not self.connected or (self.sent_a == 0.0 and self.target_a == 0.0)

    def outputs_settled(self):
        """Return True when the output is as wanted (or the device is unreachable)."""
        with self._cond:
            return not self.connected or self.output_on == self.output_wanted

    def snapshot(self):
        """Return the channel's state as a dict (for diagnostics)."""
        with self._cond:
            return {
                'axis': self.name, 'port': self.supply.line.path,
                'address': self.supply.address, 'dialect': self.supply.dialect,
                'identity': self.supply.identity, 'connected': self.connected,
                'output_on': bool(self.output_on), 'target_a': self.target_a,
                'setpoint_a': self.sent_a, 'measured_a': self.measured_a,
                'last_error': self.last_error, 'updates': self.updates,
                'faults': self.faults, **self.supply.counters,
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
                    self.measured_a = math.nan
                self._fault(f'link lost: {exc}')
                self.supply.line.close()
            except SupplyFault as exc:
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
        except (LinkLost, SupplyFault) as exc:
            self.supply.line.close()
            with self._cond:
                self.last_error = f'connect: {exc}'
            return False
        with self._cond:
            self.connected = True
            self.sent_a = 0.0  # connect() drove the device to zero
            self.output_on = None
            self._next_readback = self._next_check = 0.0
        log.info('supply %s connected on %s: %s', self.name, self.supply.line.path, identity)
        return True

    def _serve(self):
        """
        Do what is due: output change, one slew step, a readback.

        A readback goes right after a set when one is due and no newer command is waiting,
        so in a command stream it uses the line while it would idle until the next command;
        when commands keep the line busy it is deferred, for at most READBACK_MAX_DEFER_S.
        It runs on its own only when no set has gone out for a readback period: a command
        never waits behind a readback while commands keep coming.
        """
        with self._cond:
            while not self._stop.is_set():
                if self.target_a != self.sent_a or self.output_on != self.output_wanted:
                    break
                wake = max(self._next_readback, self._t_last_set + self.readback_period_s)
                wait = wake - time.monotonic()
                if wait <= 0:
                    break
                self._cond.wait(wait)
            target, wanted = self.target_a, self.output_wanted
        if self._stop.is_set():
            return
        if self.output_on != wanted:
            self.supply.set_output(wanted)
            with self._cond:
                self.output_on = wanted
        if target != self.sent_a:
            now = time.monotonic()
            max_step = self.slew_rate_a_per_s * min(now - self._t_step, STEP_DT_CAP_S)
            delta = target - self.sent_a
            setpoint = target if abs(delta) <= max_step else self.sent_a + math.copysign(
                max_step, delta)
            self.supply.set_current(setpoint)
            self._t_step = self._t_last_set = now
            with self._cond:
                self.sent_a = setpoint
                self.updates += 1
        now = time.monotonic()
        with self._cond:
            busy = self.target_a != self.sent_a
        if now >= self._next_readback + (READBACK_MAX_DEFER_S if busy else 0.0):
            self._next_readback = now + self.readback_period_s
            measured = self.supply.read_current()
            with self._cond:
                self.measured_a = measured
        if now >= self._next_check:
            self._next_check = now + CHECK_PERIOD_S
            problems = self.supply.check(self.sent_a)
            if problems:
                with self._cond:
                    self.last_error = '; '.join(problems)
                log.warning('supply %s reports %s; setpoint re-sent', self.name,
                            self.last_error)
                self.supply.set_current(self.sent_a)


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
        self._watchdog_tripped = False
        self._last_command = time.monotonic()
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

    def setpoints(self):
        """Return the setpoints the supplies hold (3,) in A."""
        return np.array([ch.sent_a for ch in self.channels])

    def snapshots(self):
        """Return one dict per supply (for diagnostics)."""
        return [ch.snapshot() for ch in self.channels]

    def status(self):
        """Return (level, message) for the bank: 'ok', 'warn' or 'error'."""
        if self._estop:
            return 'warn', 'estop active: outputs zero and off'
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
        with self._lock:
            if not on:
                self._begin_stop('disabled')
                return True, 'ramping to zero, then outputs off'
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
                return
        if self._was_enabled:
            self.enable(True)

    def _begin_stop(self, reason):
        """Zero every target now; the supervisor switches outputs off once all are at zero."""
        self._enabled = False
        self._stopping = reason
        for channel in self.channels:
            channel.request(target_a=0.0)
        log.info('coils: safe stop (%s)', reason)

    def _on_fault(self, channel, reason):
        with self._lock:
            first = not self._fault
            self._fault = f'{channel.name}: {reason}'
            for ch in self.channels:
                ch.request(target_a=0.0)
        if first:
            log.error('coils: supply %s fault, all axes to zero: %s', channel.name, reason)

    def _supervise(self):
        while not self._halt.wait(self.supervise_period_s):
            with self._lock:
                now = time.monotonic()
                if (self._enabled and not self._watchdog_tripped
                        and now - self._last_command > self.watchdog_s
                        and any(ch.target_a != 0.0 for ch in self.channels)):
                    self._watchdog_tripped = True
                    for channel in self.channels:
                        channel.request(target_a=0.0)
                    log.warning('coils: watchdog, no command for %.3g s: ramping to zero',
                                self.watchdog_s)
                if self._stopping and all(ch.at_zero() for ch in self.channels):
                    for channel in self.channels:
                        channel.request(output=False)
                    self._stopping = ''
                if (self._fault and self.connected()
                        and all(ch.at_zero() for ch in self.channels)):
                    log.info('coils: fault cleared (%s); every supply holds zero', self._fault)
                    self._fault = ''

    def shutdown(self, reason='shutdown', timeout_s=None):
        """
        Ramp to zero, switch outputs off and stop every worker; blocks until done.

        :param timeout_s: how long to wait for the ramp and the outputs (s); default: the
            ramp time at the slew limit plus one second
        :return: True when every supply confirmed zero and off
        """
        with self._lock:
            self._begin_stop(reason)
        if timeout_s is None:
            slowest = max(abs(ch.sent_a) / ch.slew_rate_a_per_s for ch in self.channels)
            timeout_s = slowest + 1.0
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not all(ch.at_zero() for ch in self.channels):
            time.sleep(0.005)
        for channel in self.channels:
            channel.request(output=False)
        while time.monotonic() < deadline + 1.0 and not all(
                ch.outputs_settled() for ch in self.channels):
            time.sleep(0.005)
        safe = all(ch.connected and ch.sent_a == 0.0 and ch.output_on is False
                   for ch in self.channels)
        self._halt.set()
        if self._supervisor.is_alive():
            self._supervisor.join(timeout=1.0)
        for channel in self.channels:
            channel.stop()
        return safe


def build_bank(ports, *, dialect, baud, addresses=(1, 1, 1), polarity_inverted=(False,) * 3,
               polarity_mode='signed', max_current_a, slew_rate_a_per_s, watchdog_s,
               readback_period_s=0.1, retries=3, reply_timeout_s=0.1, voltage_limit_v=30.0):
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
    channels = []
    for name, port, address, inverted in zip('xyz', ports, addresses, polarity_inverted):
        supply = make_supply(dialect, SerialLine(port, baud), address=address,
                             polarity_inverted=inverted, polarity_mode=polarity_mode,
                             retries=retries, reply_timeout_s=reply_timeout_s,
                             voltage_limit_v=voltage_limit_v)
        channels.append(Channel(name, supply, slew_rate_a_per_s=slew_rate_a_per_s,
                                readback_period_s=readback_period_s))
    return CoilBank(channels, max_current_a=max_current_a, watchdog_s=watchdog_s)
