"""
A bipolar coil supply behind a pseudo-terminal, answering as the device would.

Speaks the dxkdp or scpi dialect with the codecs of tentacle_coils, so driver and emulator
share one definition of the wire. The line is modelled as the driver would see a real one:
a request counts as received only when its bytes would have crossed the line at the
configured baud (10 bits per byte), the device takes ``delay_s`` to process it, and the reply
is paced at the same rate. The coil is an R-L load (coil_load.py).

Faults can be armed while running (``inject``): ``no_reply``, ``nak``, ``garble``, ``late``
(each for the next ``count`` commands), ``error`` (SCPI error queue entries) and
``disconnect`` (the port vanishes for ``duration_s``, as an unplugged USB adapter does, then
comes back under the same path; the coil keeps its current meanwhile, as a real supply does).

Every received request is logged with its arrival time, bytes and meaning, in memory and
optionally as JSON lines in a file, so tests can check exactly what reached the wire.
"""

import json
import os
import select
import threading
import time
import tty

from tentacle_coils import dxkdp, scpi
from tentacle_coils.errors import FrameError
from tentacle_sim.coil_load import CoilLoad

FAULT_KINDS = ('no_reply', 'nak', 'garble', 'late', 'error', 'disconnect')
_GARBLED_LINE = b'#\xfe?garbled\n'


class EmulatedSupply:
    """One supply: a pty, a device thread, a coil load and a fault injector."""

    def __init__(self, name, dialect, *, baud=9600, link_path=None, address=1,
                 polarity_mode='signed', delay_s=0.0005, max_current_a=50.0, load=None,
                 log_path=None):
        """
        Describe the device; ``start()`` opens the pty.

        :param name: label for logs (e.g. 'x')
        :param dialect: 'dxkdp' or 'scpi'
        :param baud: line rate used to pace requests and replies (bit/s)
        :param link_path: a stable path made a symlink to the pty (needed for reconnects)
        :param address: dxkdp bus address this device answers to
        :param polarity_mode: dxkdp 'signed' (second generation) or 'command' (first)
        :param delay_s: processing time per command (s)
        :param max_current_a: setpoints beyond this magnitude are refused (NAK / -222)
        :param load: the CoilLoad it drives (a default R-L coil if None)
        :param log_path: file to append the JSON-lines log of received requests to
        """
        if dialect not in ('dxkdp', 'scpi'):
            raise ValueError(f"dialect '{dialect}' is not dxkdp or scpi")
        self.name = name
        self.dialect = dialect
        self.byte_s = 10.0 / baud
        self.link_path = link_path
        self.address = address
        self.signed = polarity_mode == 'signed'
        self.delay_s = delay_s
        self.max_current_a = max_current_a
        self.load = load or CoilLoad()
        self.voltage_limit_v = 0.0
        self.log = []
        self._log_file = open(log_path, 'a', encoding='ascii') if log_path else None
        self._positive = True  # first-generation polarity state
        self._errors = []
        self._faults = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._master = self._slave = None
        self._reconnect_at = None
        self._buf = bytearray()
        self._buf_t = []
        self._rx_clock = 0.0
        self._thread = threading.Thread(target=self._run, name=f'emulator-{name}', daemon=True)
        self.serial = f'{abs(hash(name)) % 100000:05d}'

    # -- life cycle -------------------------------------------------------------------------
    @property
    def port(self):
        """Return the path a driver opens."""
        return self.link_path or os.ttyname(self._slave)

    @property
    def connected(self):
        """Return True while the pty exists."""
        return self._master is not None

    def start(self):
        """Open the pty and start answering."""
        self._open_pty()
        self._thread.start()
        return self

    def stop(self):
        """Stop answering and remove the pty."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._close_pty()
        if self._log_file:
            self._log_file.close()

    def _open_pty(self):
        master, slave = os.openpty()
        tty.setraw(master)
        tty.setraw(slave)  # no echo, no line editing: a fresh pty is cooked
        self._master, self._slave = master, slave
        self._buf.clear()
        self._buf_t.clear()
        if self.link_path:
            tmp = f'{self.link_path}.tmp{os.getpid()}'
            os.symlink(os.ttyname(slave), tmp)
            os.replace(tmp, self.link_path)

    def _close_pty(self):
        if self.link_path and os.path.lexists(self.link_path):
            os.unlink(self.link_path)
        for fd in (self._master, self._slave):
            if fd is not None:
                os.close(fd)
        self._master = self._slave = None

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
        if kind not in FAULT_KINDS:
            raise ValueError(f"fault '{kind}' is not one of {FAULT_KINDS}")
        with self._lock:
            if kind == 'error':
                self._errors.extend([(code, text)] * count)
            elif kind == 'disconnect':
                self._reconnect_at = time.monotonic() + duration_s
            else:
                self._faults[kind] = (count, late_s, on_current_a)

    def _take_fault(self, current_a):
        """Return (fault kind or None, late_s) for a request that sets current_a (or None)."""
        with self._lock:
            for kind in ('no_reply', 'nak', 'garble', 'late'):
                count, late_s, only_a = self._faults.get(kind, (0, 0.0, None))
                if count > 0 and (only_a is None or current_a == only_a):
                    self._faults[kind] = (count - 1, late_s, only_a)
                    return kind, late_s
        return None, 0.0

    def state(self):
        """Return a JSON-able snapshot of the device."""
        with self._lock:
            pending = {k: v[0] for k, v in self._faults.items() if v[0] > 0}
            errors = list(self._errors)
        return {
            'name': self.name, 'port': self.port if self.connected or self.link_path else None,
            'connected': self.connected, 'output_on': self.load.output_on,
            'setpoint_a': self.load.setpoint_a, 'current_a': self.load.current_a(),
            'voltage_limit_v': self.voltage_limit_v, 'received': len(self.log),
            'pending_faults': pending, 'error_queue': errors,
        }

    # -- device thread ----------------------------------------------------------------------
    def _run(self):
        while not self._stop.is_set():
            with self._lock:
                reconnect_at = self._reconnect_at
            if reconnect_at is not None:
                if self.connected:
                    self._close_pty()
                if time.monotonic() < reconnect_at:
                    self._stop.wait(0.01)
                    continue
                with self._lock:
                    self._reconnect_at = None
                self._open_pty()
            try:
                readable, _, _ = select.select([self._master], [], [], 0.02)
                if not readable:
                    continue
                chunk = os.read(self._master, 4096)
            except OSError:
                self._stop.wait(0.01)
                continue
            start = max(self._rx_clock, time.monotonic())
            self._buf += chunk
            self._buf_t += [start + (i + 1) * self.byte_s for i in range(len(chunk))]
            self._rx_clock = start + len(chunk) * self.byte_s
            for request, arrived in self._split_requests():
                self._serve(request, arrived)

    def _split_requests(self):
        """Yield (request bytes, arrival time of its last byte) for each complete request."""
        while self._buf:
            if self.dialect == 'dxkdp':
                if self._buf[0] != dxkdp.HEADER:
                    skip = self._buf.find(bytes((dxkdp.HEADER,)))
                    skip = len(self._buf) if skip < 0 else skip
                    self._record(bytes(self._buf[:skip]), self._buf_t[skip - 1],
                                 {'error': 'junk before header'})
                    self._consume(skip)
                    continue
                length = dxkdp.frame_length(self._buf)
                if length is None or len(self._buf) < length:
                    return
            else:
                end = self._buf.find(scpi.TERMINATOR)
                if end < 0:
                    if len(self._buf) > 256:
                        self._consume(len(self._buf))
                    return
                length = end + 1
            arrived = self._buf_t[length - 1]
            request = bytes(self._buf[:length])
            self._consume(length)
            yield request, arrived

    def _consume(self, n):
        del self._buf[:n]
        del self._buf_t[:n]

    def _record(self, raw, arrived, meaning):
        entry = {'t': arrived, 'port': self.name, 'hex': raw.hex(), **meaning}
        self.log.append(entry)
        if self._log_file:
            self._log_file.write(json.dumps(entry) + '\n')
            self._log_file.flush()

    def _serve(self, request, arrived):
        wait = arrived - time.monotonic()
        if wait > 0:
            time.sleep(wait)  # the request's last byte has not crossed the line yet
        fault, late_s = self._take_fault(self._requested_current(request))
        handler = self._dxkdp if self.dialect == 'dxkdp' else self._scpi
        meaning, reply = handler(request, apply=fault not in ('no_reply', 'nak'))
        if fault:
            meaning['fault'] = fault
        self._record(request, arrived, meaning)
        if fault == 'nak':
            if self.dialect == 'scpi':  # SCPI refuses in its error queue, not on the line
                with self._lock:
                    self._errors.append(scpi.DATA_OUT_OF_RANGE)
                return
            reply = bytes((dxkdp.NAK,))
        if fault == 'no_reply' or reply is None:
            return
        if fault == 'garble':
            reply = (bytes((0x5A,)) if len(reply) == 1 else reply[:-1] + bytes(
                ((reply[-1] + 1) & 0xFF,))) if self.dialect == 'dxkdp' else _GARBLED_LINE
        time.sleep(self.delay_s + (late_s if fault == 'late' else 0.0)
                   + len(reply) * self.byte_s)
        try:
            os.write(self._master, reply)
        except (OSError, TypeError):
            pass  # the port went away meanwhile

    def _requested_current(self, raw):
        """Return the current (A) a request sets, or None (malformed or not a set)."""
        try:
            if self.dialect == 'scpi':
                header, argument, _ = scpi.parse_command(raw)
                return float(argument) if header == 'CURR' else None
            values = dxkdp.decode_request(dxkdp.decode_frame(raw))
        except (FrameError, ValueError):
            return None
        if 'current_count' not in values:
            return None
        return self._current_from_count(values['current_count'])

    # -- dialects ---------------------------------------------------------------------------
    def _current_from_count(self, count):
        magnitude_or_signed = dxkdp.count_to_current(count, self.signed)
        return magnitude_or_signed if self.signed else (
            magnitude_or_signed if self._positive else -magnitude_or_signed)

    def _dxkdp(self, raw, apply):
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

    def _scpi(self, raw, apply):
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
