"""
One bipolar supply's commands over a SerialLine, in the configured wire dialect.

A supply object is driven by exactly one thread (its channel in coil_bank.py). Every
exchange has a deadline and a bounded number of attempts; after the last it raises
SupplyFault with the reason. Currents are in the coil frame: positive means the coil's
positive field direction; ``polarity_inverted`` flips the sign at the wire for a supply wired
the other way round.
"""

from tentacle_coils import dxkdp, scpi
from tentacle_coils.errors import ConfigError, FrameError, NakError, Superseded, SupplyFault
from tentacle_common.attempts import Attempts


class Supply:
    """What every dialect provides: connect, output on/off, set and read current, read back."""

    dialect = ''
    resolution_a = 0.01  # smallest current step the wire carries (A)
    set_bytes = 0  # bytes of the shortest current set command on the wire
    verify_period_s = None  # read the held state back this often (s); None: only to confirm

    def __init__(self, line, *, address=1, polarity_inverted=False, retries=3,
                 reply_timeout_s=0.1, max_turnaround_s=0.25, voltage_limit_v=30.0):
        """
        Bind to a line.

        :param line: a SerialLine (opened by the caller), or a line with the same methods
        :param address: bus address (dxkdp)
        :param polarity_inverted: the supply is wired reversed
        :param retries: attempts after the first before SupplyFault
        :param reply_timeout_s: how long past the bytes' own wire time to wait for a reply
        :param max_turnaround_s: the device's worst time to answer: after a timeout the line
            must be quiet this long before the next request, so a late reply is dropped
        :param voltage_limit_v: compliance voltage programmed at connect (dxkdp)
        """
        self.line = line
        self.address = int(address)
        self.sign = -1.0 if polarity_inverted else 1.0
        self.reply_timeout_s = float(reply_timeout_s)
        self.voltage_limit_v = float(voltage_limit_v)
        self.attempts = Attempts(line, retries=retries, max_turnaround_s=max_turnaround_s,
                                 fault=SupplyFault)
        self.identity = ''

    @property
    def counters(self):
        """Return what the exchanges met: commands, retries, NAKs, timeouts, ..."""
        return self.attempts.counters

    def connect(self):
        """
        Check the device answers and program its limits; return its identity.

        The current it holds is left as it is: read_held() tells it, and the channel ramps
        it to zero at the slew limit (a jump to zero in a big coil is a step too).
        """
        raise NotImplementedError

    def set_output(self, on):
        """Switch the output on or off."""
        raise NotImplementedError

    def set_current(self, current_a, still_wanted=None):
        """
        Set the current setpoint (A, coil frame).

        :param still_wanted: asked right before every write of the set (first send and
            retries alike); False drops it
        :raises Superseded: still_wanted() said no; ``ambiguous`` if the device may have
            taken an earlier, unanswered attempt
        """
        raise NotImplementedError

    def read_current(self):
        """Return the measured current (A, coil frame)."""
        raise NotImplementedError

    def read_held(self):
        """Return (setpoint in A, coil frame; output on) as the device itself reports them."""
        raise NotImplementedError

    def errors(self):
        """Return the errors the device has queued (text, oldest first); none by default."""
        return []


class DxkdpSupply(Supply):
    """
    A Dexing DXKDP unit: binary frames, each set command answered by ACK or NAK.

    ``polarity_mode`` is ``signed`` (second generation: negative current as two's complement)
    or ``command`` (first generation: polarity set by command 0x24, magnitude by 0x22).
    READ_STATE (0x28) is taken to report the output state and the programmed setpoints, and
    READ_OUTPUT (0x26) what is measured: confirm on your own units.
    """

    dialect = 'dxkdp'
    resolution_a = dxkdp.AMPS_PER_COUNT
    set_bytes = dxkdp.wire_bytes(dxkdp.Code.CURRENT)[0]

    def __init__(self, line, *, polarity_mode='signed', **kwargs):
        """Bind to a line; see Supply for the other arguments."""
        super().__init__(line, **kwargs)
        if polarity_mode not in ('signed', 'command'):
            raise ConfigError(f"dxkdp polarity_mode '{polarity_mode}' is not signed or command")
        self.signed = polarity_mode == 'signed'
        self._positive = None  # device polarity in command mode; None: unknown
        self._magnitude_a = 0.0  # current magnitude last set in command mode (A)

    def _exchange(self, frame, verify=None, still_wanted=None):
        """Send one request; return None for an ACKed set, the reply Frame for a read."""
        request_bytes, reply_bytes = dxkdp.wire_bytes(frame[2])
        wait_s = self.line.wire_time_s(request_bytes + reply_bytes) + self.reply_timeout_s
        code = dxkdp.Code(frame[2])

        def attempt():
            self.line.write(frame)
            deadline = self.line.now() + wait_s
            if dxkdp.COMMANDS[code].reply_data_len is None:
                if not dxkdp.parse_ack(self.line.read_exact(1, deadline)[0]):
                    raise NakError(f'{self.line.path}: {code.name} answered NAK')
                return None
            head = self.line.read_exact(4, deadline)
            if head[0] != dxkdp.HEADER:
                raise FrameError(f'reply starts {head.hex(" ")}, not AA')
            reply = dxkdp.decode_frame(head + self.line.read_exact(
                dxkdp.frame_length(head) - 4, deadline))
            if (reply.address, reply.code) != (self.address, code):
                raise FrameError(f'reply from address {reply.address} code {reply.code:02x} '
                                 f'to a request for address {self.address} code {code:02x}')
            return reply

        return self.attempts.run(code.name, attempt, verify, still_wanted)

    def _read_state(self):
        return dxkdp.parse_reading(self._exchange(dxkdp.read_state(self.address)), self.signed)

    def _state_differs(self, output_on=None, current_a=None, voltage_v=None):
        """Return what the device's state (READ_STATE) has other than expected, or ''."""
        state = self._read_state()
        if output_on is not None and state.output_on != output_on:
            return f'output is {"on" if state.output_on else "off"}'
        if current_a is not None and abs(state.current_a - current_a) > dxkdp.AMPS_PER_COUNT / 2:
            return f'current setpoint is {state.current_a:.2f} A, not {current_a:.2f} A'
        if voltage_v is not None and abs(state.voltage_v - voltage_v) > (
                dxkdp.VOLTS_PER_COUNT / 2):
            return f'voltage setpoint is {state.voltage_v:.2f} V, not {voltage_v:.2f} V'
        return ''

    def connect(self):
        """Read the state (presence) and program the voltage limit; see Supply.connect."""
        self.attempts.resync()
        state = self._read_state()
        # First-generation units do not report their polarity: until a set at zero fixes
        # it, only the magnitude changes, so a current found here ramps down as it flows.
        self._positive = None
        self._magnitude_a = abs(state.current_a)
        self._exchange(dxkdp.set_voltage(self.address, self.voltage_limit_v),
                       lambda: self._state_differs(voltage_v=self.voltage_limit_v))
        output = 'on' if state.output_on else 'off'
        self.identity = f'dxkdp address {self.address} (output {output}, ' \
                        f'{state.current_a:.2f} A)'
        return self.identity

    def set_output(self, on):
        """Switch the output on or off."""
        self._exchange(dxkdp.set_output(self.address, on),
                       lambda: self._state_differs(output_on=on))

    def set_current(self, current_a, still_wanted=None):
        """Set the current setpoint (A, coil frame); see Supply.set_current."""
        device_a = self.sign * current_a
        if self.signed:
            self._exchange(dxkdp.set_current(self.address, device_a, signed=True),
                           lambda: self._state_differs(current_a=device_a), still_wanted)
            return
        positive = device_a >= 0
        if positive != self._positive and (self._positive is not None
                                           or self._magnitude_a == 0.0):
            if self._magnitude_a != 0.0:  # polarity changes at zero only: no current step
                self._exchange(dxkdp.set_current(self.address, 0.0),
                               lambda: self._state_differs(current_a=0.0))
                self._magnitude_a = 0.0
            self._exchange(dxkdp.set_polarity(self.address, positive, positive),
                           still_wanted=still_wanted)
            self._positive = positive
        self._exchange(dxkdp.set_current(self.address, abs(device_a)),
                       lambda: self._state_differs(current_a=abs(device_a)), still_wanted)
        self._magnitude_a = abs(device_a)

    def _coil_frame(self, device_a):
        if not self.signed and self._positive is False:
            device_a = -device_a
        return self.sign * device_a

    def read_current(self):
        """Return the measured current (A, coil frame)."""
        reading = dxkdp.parse_reading(self._exchange(dxkdp.read_output(self.address)),
                                      self.signed)
        return self._coil_frame(reading.current_a)

    def read_held(self):
        """Return (setpoint in A, coil frame; output on) from READ_STATE."""
        state = self._read_state()
        return self._coil_frame(state.current_a), state.output_on


class ScpiSupply(Supply):
    """A generic SCPI bipolar supply: set commands get no reply, queries one line each."""

    dialect = 'scpi'
    resolution_a = 1e-4
    set_bytes = len(scpi.set_current(0.0))
    verify_period_s = 1.0  # a lost set is silent: read the setpoint back on this period

    def _query(self, request, parse):
        wait_s = self.line.wire_time_s(len(request) + 24) + self.reply_timeout_s

        def attempt():
            self.line.write(request)
            return parse(self.line.read_until(scpi.TERMINATOR, self.line.now() + wait_s))

        return self.attempts.run(request.decode('ascii').strip(), attempt)

    def connect(self):
        """Identify the device and drain its error queue; see Supply.connect."""
        self.attempts.resync()
        maker, model, serial_no, firmware = self._query(scpi.identify(), scpi.parse_identity)
        self.errors()
        self.identity = f'{maker} {model} s/n {serial_no} fw {firmware}'
        return self.identity

    def set_output(self, on):
        """Switch the output on or off and confirm with ``OUTP?``."""
        self.counters['commands'] += 1
        self.line.write(scpi.set_output(on))
        if self.read_output() != on:
            raise SupplyFault(f'{self.line.path}: output did not switch {"on" if on else "off"}')

    def set_current(self, current_a, still_wanted=None):
        """Set the current setpoint (A, coil frame); SCPI sends no reply. See Supply."""
        if still_wanted is not None and not still_wanted():
            raise Superseded(f'{self.line.path}: CURR {current_a:.4f} no longer wanted')
        self.counters['commands'] += 1
        self.line.write(scpi.set_current(self.sign * current_a))

    def read_current(self):
        """Return the measured current (A, coil frame)."""
        return self.sign * self._query(scpi.measure_current(), scpi.parse_float)

    def read_setpoint(self):
        """Return the setpoint the device holds (A, coil frame)."""
        return self.sign * self._query(scpi.query_setpoint(), scpi.parse_float)

    def read_output(self):
        """Return whether the output is on (``OUTP?``)."""
        return self._query(scpi.query_output(), scpi.parse_bool)

    def read_held(self):
        """Return (setpoint in A, coil frame; output on) from ``CURR?`` and ``OUTP?``."""
        return self.read_setpoint(), self.read_output()

    def errors(self, max_entries=8):
        """Return the queued ``SYST:ERR?`` entries as text, oldest first."""
        errors = []
        for _ in range(max_entries):
            code, text = self._query(scpi.query_error(), scpi.parse_error)
            if code == 0:
                break
            errors.append(f'{code},"{text}"')
        return errors


DIALECTS = {'dxkdp': DxkdpSupply, 'scpi': ScpiSupply}


def make_supply(dialect, line, **kwargs):
    """
    Return a Supply of the named dialect bound to line.

    :raises ConfigError: an unknown dialect
    """
    try:
        cls = DIALECTS[dialect]
    except KeyError:
        raise ConfigError(f"dialect '{dialect}' is not one of {sorted(DIALECTS)}") from None
    if cls is not DxkdpSupply:
        kwargs.pop('polarity_mode', None)
    return cls(line, **kwargs)
