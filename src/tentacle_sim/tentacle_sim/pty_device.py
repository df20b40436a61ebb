"""
A device behind a pseudo-terminal: the line, its pacing, faults and the log every emulator has.

A request counts as received only when its bytes would have crossed the line at the
configured baud (10 bits per byte); the device takes ``delay_s`` to process it, and its reply
is paced at the same rate. Line faults can be armed while running (``inject``): ``no_reply``
(the request is lost), ``drop_reply`` (it is obeyed, its answer lost), ``garble``, ``late``
(each for the next ``count`` requests, optionally only those a device says match) and
``disconnect`` (the port vanishes for ``duration_s``, as an unplugged USB
adapter does, then comes back under the same path). Every received request is logged with
its arrival time, bytes and meaning, in memory and optionally as JSON lines in a file, so
tests can check exactly what reached the wire.

A device model subclasses PtyDevice and says how requests are framed (``frame``), what each
means and what it answers (``handle``), how its replies garble (``garble``) and, if it can
refuse a command, how (``refusal``, fault ``nak``).
"""

import json
import os
import select
import threading
import time
import tty

POLL_S = 0.005  # how often the device thread looks for bytes, and for what it sends itself
UNAPPLIED_FAULTS = ('no_reply', 'nak')  # a request with one of these is not acted on


class PtyDevice:
    """A pty, a device thread, line pacing, fault injection and the received-request log."""

    FAULT_KINDS = ('no_reply', 'drop_reply', 'garble', 'late', 'disconnect')
    REQUEST_FAULTS = ('no_reply', 'drop_reply', 'nak', 'garble', 'late')  # in this order
    # Faults that only touch the reply: a request with none (a SCPI set) is not theirs, so
    # an armed one waits for the next request that is answered.
    REPLY_FAULTS = ('drop_reply', 'garble', 'late')

    def __init__(self, name, *, baud=9600, link_path=None, delay_s=0.0005, log_path=None):
        """
        Describe the line; ``start()`` opens the pty.

        :param name: label for logs (e.g. 'x')
        :param baud: line rate used to pace requests and replies (bit/s)
        :param link_path: a stable path made a symlink to the pty (needed for reconnects)
        :param delay_s: processing time per request (s)
        :param log_path: file to append the JSON-lines log of received requests to
        """
        self.name = name
        self.byte_s = 10.0 / baud
        self.link_path = link_path
        self.delay_s = delay_s
        self.log = []
        self._log_file = open(log_path, 'a', encoding='ascii') if log_path else None
        self._faults = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._master = self._slave = None
        self._reconnect_at = None
        self._buf = bytearray()
        self._buf_t = []
        self._rx_clock = 0.0
        self._thread = threading.Thread(target=self._run, name=f'emulator-{name}', daemon=True)

    # -- what a device model says -----------------------------------------------------------
    def frame(self, buf):
        """
        Return (what, n) for the start of the received bytes.

        ('request', n): the first n bytes are one request; ('junk', n): n bytes to log and
        drop; ('drop', n): n bytes to drop unlogged; ('wait', 0): not a whole request yet.
        """
        raise NotImplementedError

    def handle(self, request, apply):
        """Return (meaning for the log, reply bytes or None); act on it only if apply."""
        raise NotImplementedError

    def answered(self, request):
        """Return whether the device answers this request (reply faults need an answer)."""
        return True

    def garble(self, reply):
        """Return the reply as a bad line would deliver it."""
        return reply[:-1] + bytes(((reply[-1] + 1) & 0xFF,))

    def refusal(self):
        """Return what the device answers to a command it refuses (fault 'nak'), or None."""
        raise ValueError(f'{type(self).__name__} has no refusal')

    def matches(self, request, match):
        """Return whether an armed fault with this match applies to the request."""
        return match is None

    def poll(self):
        """Return bytes the device sends of its own accord now (a deferred reply), or None."""
        return None

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

    # -- faults -----------------------------------------------------------------------------
    def inject(self, kind, count=1, late_s=0.2, duration_s=1.0, match=None):
        """
        Arm a line fault.

        :param kind: one of FAULT_KINDS
        :param count: requests affected (no_reply, nak, garble, late)
        :param late_s: extra reply delay for 'late' (s)
        :param duration_s: how long the port is gone for 'disconnect' (s)
        :param match: only requests the device says match count (``matches``)
        """
        if kind not in self.FAULT_KINDS:
            raise ValueError(f"fault '{kind}' is not one of {self.FAULT_KINDS}")
        with self._lock:
            if kind == 'disconnect':
                self._reconnect_at = time.monotonic() + duration_s
            else:
                self._faults[kind] = (count, late_s, match)

    def _take_fault(self, request):
        """Return (fault kind or None, late_s) for a request, using up one armed count."""
        with self._lock:
            armed = [(kind, self._faults.get(kind)) for kind in self.REQUEST_FAULTS]
        for kind, fault in armed:
            if kind in self.REPLY_FAULTS and not self.answered(request):
                continue
            if fault and fault[0] > 0 and self.matches(request, fault[2]):
                with self._lock:
                    count, late_s, match = self._faults[kind]
                    self._faults[kind] = (count - 1, late_s, match)
                return kind, late_s
        return None, 0.0

    def pending_faults(self):
        """Return {kind: requests still affected}."""
        with self._lock:
            return {k: v[0] for k, v in self._faults.items() if v[0] > 0}

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
            unsolicited = self.poll()
            if unsolicited:
                self._send(unsolicited)
            try:
                readable, _, _ = select.select([self._master], [], [], POLL_S)
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
            what, n = self.frame(self._buf)
            if what == 'wait':
                return
            if what == 'junk':
                self._record(bytes(self._buf[:n]), self._buf_t[n - 1],
                             {'error': 'junk before header'})
            if what != 'request':
                self._consume(n)
                continue
            arrived = self._buf_t[n - 1]
            request = bytes(self._buf[:n])
            self._consume(n)
            yield request, arrived

    def _consume(self, n):
        del self._buf[:n]
        del self._buf_t[:n]

    def _record(self, raw, arrived, meaning):
        # t: when the last byte arrived on the modelled line; served_t: when the device acted
        # on it (and took an armed fault), which can be later: a request on the line when a
        # fault is armed arrived before it and is served after it.
        entry = {'t': arrived, 'served_t': time.monotonic(), 'port': self.name,
                 'hex': raw.hex(), **meaning}
        self.log.append(entry)
        if self._log_file:
            self._log_file.write(json.dumps(entry) + '\n')
            self._log_file.flush()

    def _serve(self, request, arrived):
        wait = arrived - time.monotonic()
        if wait > 0:
            time.sleep(wait)  # the request's last byte has not crossed the line yet
        fault, late_s = self._take_fault(request)
        meaning, reply = self.handle(request, apply=fault not in UNAPPLIED_FAULTS)
        if fault:
            meaning['fault'] = fault
        self._record(request, arrived, meaning)
        if fault == 'nak':
            reply = self.refusal()
        if fault in ('no_reply', 'drop_reply') or reply is None:
            return
        if fault == 'garble':
            reply = self.garble(reply)
        self._send(reply, self.delay_s + (late_s if fault == 'late' else 0.0))

    def _send(self, reply, delay_s=0.0):
        """Write reply bytes after delay_s and their time on the line."""
        time.sleep(delay_s + len(reply) * self.byte_s)
        try:
            os.write(self._master, reply)
        except (OSError, TypeError):
            pass  # the port went away meanwhile
