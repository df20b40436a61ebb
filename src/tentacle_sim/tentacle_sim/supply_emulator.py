"""
A bipolar coil supply behind a pseudo-terminal, answering as the device would.

One device model per dialect, DxkdpSupply and ScpiSupply (the factory ``make_supply(name,
dialect)`` makes the right one; each has a serial number that depends on its name only, the
same in every run), on the line of pty_device.PtyDevice: pacing at the configured baud,
processing delay, line faults and the log of every received request. They speak with the
codecs of tentacle_coils, so driver and emulator share one definition of the wire (the
protocol tests in tentacle_coils check the driver against scripted bytes instead). The coil
is an R-L load (coil_load.py).

Faults beyond the line's (``inject``): ``nak`` (the next ``count`` commands refused: a NAK
byte, or SCPI's -222 in the error queue), ``error`` (SCPI error queue entries), and
``on_current_a`` to arm no_reply, nak, garble or late for commands that set that current
only (e.g. 0.0 for the last set of a ramp to zero). A disconnected supply's coil keeps its
current, as a real supply's does.
"""

import zlib

from tentacle_coils import dxkdp, scpi
from tentacle_coils.errors import FrameError
from tentacle_sim.coil_load import CoilLoad
from tentacle_sim.pty_device import PtyDevice

FAULT_KINDS = ('no_reply', 'nak', 'garble', 'late', 'error', 'disconnect')
_GARBLED_LINE = b'#\xfe?garbled\n'


def make_supply(name, dialect, **kwargs):
    """
    Return the device model of the dialect, not started (SupplyModel's keyword arguments).

    :param dialect: 'dxkdp' or 'scpi'
    :raises ValueError: another dialect
    """
    models = {'dxkdp': DxkdpSupply, 'scpi': ScpiSupply}
    if dialect not in models:
        raise ValueError(f"dialect '{dialect}' is not dxkdp or scpi")
    return models[dialect](name, **kwargs)


def serial_number(name):
    """Return a five-digit serial number made from the name: the same in every run."""
    # Not hash(): Python salts str hashes per process (PYTHONHASHSEED).
    return f'{zlib.crc32(name.encode("utf-8")) % 100000:05d}'


class SupplyModel(PtyDevice):
    """One supply: the line, a coil load, and what both dialects share (make_supply)."""

    FAULT_KINDS = FAULT_KINDS
    dialect = None  # each model's wire dialect

    def __init__(self, name, *, baud=9600, link_path=None, address=1,
                 polarity_mode='signed', delay_s=0.0005, max_current_a=50.0, load=None,
                 log_path=None):
        """
        Describe the device; ``start()`` opens the pty.

        :param name: label for logs (e.g. 'x')
        :param baud: line rate used to pace requests and replies (bit/s, positive)
        :param link_path: a stable path made a symlink to the pty (needed for reconnects)
        :param address: dxkdp bus address this device answers to
        :param polarity_mode: dxkdp 'signed' (second generation) or 'command' (first)
        :param delay_s: processing time per command (s)
        :param max_current_a: setpoints beyond this magnitude are refused (NAK / -222)
        :param load: the CoilLoad it drives (a default R-L coil if None)
        :param log_path: file to append the JSON-lines log of received requests to
        :raises ValueError: a baud that is not positive
        """
        if not baud > 0:
            raise ValueError(f'baud {baud!r}: a line rate must be positive (bit/s)')
        super().__init__(name, baud=baud, link_path=link_path, delay_s=delay_s,
                         log_path=log_path)
        self.address = address
        self.signed = polarity_mode == 'signed'
        self.max_current_a = max_current_a
        self.load = load or CoilLoad()
        self.voltage_limit_v = 0.0
        self._positive = True  # first-generation polarity state
        self._errors = []
        self.serial = serial_number(name)

    # -- faults and state -------------------------------------------------------------------
    def inject(self, kind, count=1, late_s=0.2, duration_s=1.0, code=-222,
               text='Data out of range', on_current_a=None):
        """
        Arm a fault.

        :param kind: one of FAULT_KINDS
        :param count: commands affected (no_reply, nak, garble, late) or entries (error)
        :param late_s: extra reply delay for 'late' (s)
        :param duration_s: how long the port is gone for 'disconnect' (s)
        :param code: error code for 'error'
        :param text: error text for 'error'
        :param on_current_a: only commands that set this current (A) count (no_reply, nak,
            garble, late), e.g. 0.0 for the last set of a ramp to zero
        """
        if kind == 'error':
            with self._lock:
                self._errors.extend([(code, text)] * count)
            return
        super().inject(kind, count, late_s, duration_s, match=on_current_a)

    def matches(self, request, match):
        """Return whether a fault armed for current ``match`` (A, or None: any) applies."""
        return match is None or self.requested_current(request) == match

    def state(self):
        """Return a JSON-able snapshot of the device."""
        with self._lock:
            errors = list(self._errors)
        return {
            'name': self.name, 'port': self.port if self.connected or self.link_path else None,
            'connected': self.connected, 'output_on': self.load.output_on,
            'setpoint_a': self.load.setpoint_a, 'current_a': self.load.current_a(),
            'voltage_limit_v': self.voltage_limit_v, 'received': len(self.log),
            'pending_faults': self.pending_faults(), 'error_queue': errors,
        }

    def requested_current(self, request):
        """Return the current (A) a request sets, or None (malformed or not a set)."""
        raise NotImplementedError


class DxkdpSupply(SupplyModel):
    """A supply on the dxkdp binary dialect (dxkdp.py): framed requests, ACK / NAK."""

    dialect = 'dxkdp'

    def frame(self, buf):
        """Return (what, n): a frame by its header and length, junk before a header."""
        if buf[0] != dxkdp.HEADER:
            skip = buf.find(bytes((dxkdp.HEADER,)))
            return 'junk', len(buf) if skip < 0 else skip
        length = dxkdp.frame_length(buf)
        return ('wait', 0) if length is None or len(buf) < length else ('request', length)

    def garble(self, reply):
        """Return a corrupted reply: an ACK or NAK byte becomes noise, a frame's checksum."""
        return bytes((0x5A,)) if len(reply) == 1 else super().garble(reply)

    def refusal(self):
        """Return a NAK."""
        return bytes((dxkdp.NAK,))

    def requested_current(self, request):
        """Return the current (A) a request sets, or None (malformed or not a set)."""
        try:
            values = dxkdp.decode_request(dxkdp.decode_frame(request))
        except (FrameError, ValueError):
            return None
        if 'current_count' not in values:
            return None
        return self._current_from_count(values['current_count'])

    def _current_from_count(self, count):
        magnitude_or_signed = dxkdp.count_to_current(count, self.signed)
        return magnitude_or_signed if self.signed else (
            magnitude_or_signed if self._positive else -magnitude_or_signed)

    def handle(self, raw, apply):
        """Return (meaning for the log, reply bytes or None)."""
        ack, nak = bytes((dxkdp.ACK,)), bytes((dxkdp.NAK,))
        try:
            frame = dxkdp.decode_frame(raw)
            values = dxkdp.decode_request(frame)
        except FrameError as exc:
            return {'error': str(exc)}, nak
        if frame.address != self.address:
            return {'error': f'address {frame.address} is not mine'}, None
        code = dxkdp.Code(frame.code)
        meaning = {'command': code.name}
        if code in (dxkdp.Code.READ_OUTPUT, dxkdp.Code.READ_STATE):
            # READ_OUTPUT: what is measured; READ_STATE: output state and the setpoints.
            if code == dxkdp.Code.READ_OUTPUT:
                voltage_v, current_a = self.load.voltage_v(), self.load.current_a()
            else:
                voltage_v, current_a = self.voltage_limit_v, self.load.setpoint_a
            reading = dxkdp.Reading(voltage_v=voltage_v,
                                    current_a=current_a if self.signed else abs(current_a),
                                    output_on=self.load.output_on, constant_current=True)
            return meaning, dxkdp.encode_reading(self.address, code, reading, self.signed)
        if code == dxkdp.Code.POLARITY and self.signed:
            return {**meaning, 'error': 'second-generation units have no 0x24'}, nak
        if 'voltage_count' in values:
            meaning['voltage_v'] = values['voltage_count'] * dxkdp.VOLTS_PER_COUNT
        if 'current_count' in values:
            meaning['current_a'] = self._current_from_count(values['current_count'])
            if abs(meaning['current_a']) > self.max_current_a:
                return {**meaning, 'error': 'beyond rating'}, nak
        if 'output_on' in values:
            meaning['output_on'] = values['output_on']
        if code == dxkdp.Code.POLARITY:
            meaning['current_positive'] = values['current_positive']
        if apply:
            if code == dxkdp.Code.POLARITY:
                if values['current_positive'] != self._positive:
                    self._positive = values['current_positive']
                    self.load.drive(setpoint_a=-self.load.setpoint_a)
            if 'voltage_v' in meaning:
                self.voltage_limit_v = meaning['voltage_v']
            self.load.drive(setpoint_a=meaning.get('current_a'),
                            output_on=meaning.get('output_on'))
        return meaning, ack


class ScpiSupply(SupplyModel):
    """A supply on SCPI (scpi.py): lines, queries answered, refusals in the error queue."""

    dialect = 'scpi'

    def frame(self, buf):
        """Return (what, n): a line to its terminator (a runaway line is dropped)."""
        end = buf.find(scpi.TERMINATOR)
        if end < 0:
            return ('drop', len(buf)) if len(buf) > 256 else ('wait', 0)
        return 'request', end + 1

    def answered(self, request):
        """Return whether the request is a query (SCPI answers queries only)."""
        return request.rstrip(b'\r\n').split(b' ', 1)[0].endswith(b'?')

    def garble(self, reply):
        """Return a line of noise."""
        return _GARBLED_LINE

    def refusal(self):
        """Queue -222 (SCPI refuses in its error queue, not on the line); answer nothing."""
        with self._lock:
            self._errors.append(scpi.DATA_OUT_OF_RANGE)
        return None

    def requested_current(self, request):
        """Return the current (A) a request sets, or None (malformed or not a set)."""
        try:
            header, argument, _ = scpi.parse_command(request)
            return float(argument) if header == 'CURR' else None
        except (FrameError, ValueError):
            return None

    def handle(self, raw, apply):
        """Return (meaning for the log, reply bytes or None)."""
        try:
            header, argument, _ = scpi.parse_command(raw)
        except FrameError as exc:
            code = scpi.UNDEFINED_HEADER if '-113' in str(exc) else scpi.DATA_OUT_OF_RANGE
            with self._lock:
                self._errors.append(code)
            return {'error': str(exc)}, None
        meaning = {'command': header}
        if header == 'CURR':
            try:
                current_a = float(argument)
            except ValueError:
                current_a = float('nan')
            meaning['current_a'] = current_a
            if not abs(current_a) <= self.max_current_a:
                with self._lock:
                    self._errors.append(scpi.DATA_OUT_OF_RANGE)
                return {**meaning, 'error': 'data out of range'}, None
            if apply:
                self.load.drive(setpoint_a=current_a)
            return meaning, None
        if header == 'OUTP':
            on = argument.upper() in ('ON', '1')
            if argument.upper() not in ('ON', 'OFF', '1', '0'):
                with self._lock:
                    self._errors.append(scpi.DATA_OUT_OF_RANGE)
                return {**meaning, 'error': 'bad argument'}, None
            meaning['output_on'] = on
            if apply:
                self.load.drive(output_on=on)
            return meaning, None
        if header == 'SYST:ERR?':
            with self._lock:
                entry = self._errors.pop(0) if self._errors else scpi.NO_ERROR
            return meaning, scpi.format_error(*entry)
        if header == '*IDN?':
            return meaning, f'Emulated,BPS-{self.name},{self.serial},1.0\n'.encode('ascii')
        if header == 'OUTP?':
            return meaning, b'1\n' if self.load.output_on else b'0\n'
        value = {'CURR?': self.load.setpoint_a, 'MEAS:CURR?': self.load.current_a(),
                 'MEAS:VOLT?': self.load.voltage_v()}[header]
        return meaning, scpi.format_value(value)
