"""
A serial line whose far end is a script, on a virtual clock: protocol tests for drivers.

It has the methods of tentacle_common.serial_line.SerialLine, and its own clock: ``now()``
starts at 0 and moves only as the line would (writes paced at the baud rate, reads waiting
for bytes or their deadline, drains waiting for quiet). A test lists the exact exchange,
``Exchange(expect=request bytes, reply=reply bytes, after_s=device turnaround)``, or gives
a ``responder(request) -> (reply, after_s)``; a request other than the next expected one,
one past the end of the script, or script or reply bytes left over at ``finish()`` fail the
test. Timing therefore decides nothing about the machine running the test.
"""

from dataclasses import dataclass

from tentacle_common.errors import LinkLost, ReplyTimeout
from tentacle_common.serial_line import BITS_PER_BYTE


class ScriptError(AssertionError):
    """The driver did not do what the script expects."""


@dataclass(frozen=True)
class Exchange:
    """One request the driver must send, and what the device answers, how late (s)."""

    expect: bytes
    reply: bytes = b''
    after_s: float = 0.0005


class ScriptedLine:
    """A line to a scripted device; see the module docstring."""

    def __init__(self, script=(), *, baud=9600, responder=None, path='scripted'):
        """
        Set the script (a sequence of Exchange) or a responder, the baud rate and a name.

        :param responder: called with each request's bytes when there is no script;
            returns (reply bytes, turnaround s)
        """
        self.script = list(script)
        self.responder = responder
        self.baud = int(baud)
        self.path = path
        self.sent = []  # (time the last byte left the line, bytes)
        self._clock = 0.0
        self._tx_free_at = 0.0
        self._incoming = []  # (arrival time, byte value), in time order
        self._device_free_at = 0.0
        self._open = False

    # -- what SerialLine offers -------------------------------------------------------------
    def now(self):
        """Return the virtual clock (s)."""
        return self._clock

    @property
    def tx_free_at(self):
        """Return when the last byte written so far leaves the line (s)."""
        return self._tx_free_at

    @property
    def is_open(self):
        """Return True while open."""
        return self._open

    def wire_time_s(self, n_bytes):
        """Return the time n_bytes take on the line (s)."""
        return n_bytes * BITS_PER_BYTE / self.baud

    def open(self):  # noqa: A003 (the serial-port verb)
        """Open the line."""
        self._open = True

    def close(self):
        """Close the line."""
        self._open = False

    def write(self, data):
        """Send a request as SerialLine does (one write queued at most); return its end."""
        if not self._open:
            raise LinkLost(f'{self.path} is not open')
        data = bytes(data)
        wire_s = self.wire_time_s(len(data))
        self._clock = max(self._clock, self._tx_free_at - wire_s)
        self._tx_free_at = max(self._clock, self._tx_free_at) + wire_s
        self.sent.append((self._tx_free_at, data))
        reply, after_s = self._answer(data)
        # The device answers in order: a reply starts after the one before it has ended.
        start = max(self._tx_free_at + after_s, self._device_free_at)
        byte_s = self.wire_time_s(1)
        self._incoming += [(start + (i + 1) * byte_s, b) for i, b in enumerate(reply)]
        self._device_free_at = start + len(reply) * byte_s
        return self._tx_free_at

    def read_exact(self, n_bytes, deadline):
        """Return n_bytes once they have arrived, or raise ReplyTimeout at the deadline."""
        if len(self._incoming) >= n_bytes and self._incoming[n_bytes - 1][0] <= deadline:
            self._clock = max(self._clock, self._incoming[n_bytes - 1][0])
            return self._take(n_bytes)
        self._time_out(deadline, f'{n_bytes} bytes')

    def _time_out(self, deadline, wanted):
        """Wait until the deadline, drop what arrived by then (as SerialLine does), raise."""
        self._clock = max(self._clock, deadline)
        got = self._take(self._arrived())
        raise ReplyTimeout(f'{self.path}: {len(got)} bytes by the deadline, wanted {wanted}')

    def _arrived(self):
        return sum(1 for t, _ in self._incoming if t <= self._clock)

    def wait_input(self, deadline):
        """Return True once a byte has arrived (none taken), False at the deadline."""
        if self._incoming and self._incoming[0][0] <= deadline:
            self._clock = max(self._clock, self._incoming[0][0])
            return True
        self._clock = max(self._clock, deadline)
        return False

    def read_until(self, terminator, deadline, max_bytes=256):
        """Return the bytes up to and including terminator, or raise ReplyTimeout."""
        line = bytearray()
        for i, (t, b) in enumerate(self._incoming):
            if t > deadline or i >= max_bytes:
                break
            line.append(b)
            if line.endswith(terminator):
                self._clock = max(self._clock, t)
                return self._take(i + 1)
        self._time_out(deadline, 'a line')

    def discard_input(self, quiet_s=0.0, max_s=5.0):
        """Drop what has arrived and what arrives until quiet for quiet_s; return the count."""
        dropped = 0
        while True:
            dropped += len(self._take(self._arrived()))
            if not self._incoming or self._incoming[0][0] > self._clock + quiet_s:
                self._clock += quiet_s
                return dropped
            self._clock = self._incoming[0][0]

    def advance(self, dt_s):
        """Let dt_s seconds pass (the driver is idle meanwhile)."""
        self._clock += dt_s

    # -- checks -----------------------------------------------------------------------------
    def finish(self):
        """Fail unless every scripted request was sent and every reply byte was read."""
        if self.script:
            raise ScriptError(f'{self.path}: {len(self.script)} scripted requests never sent, '
                              f'next {self.script[0].expect.hex(" ")}')
        if self._incoming:
            raise ScriptError(f'{self.path}: reply bytes never read: '
                              f'{bytes(b for _, b in self._incoming).hex(" ")}')

    def _answer(self, data):
        if self.responder is not None and not self.script:
            return self.responder(data)
        if not self.script:
            raise ScriptError(f'{self.path}: unexpected request {data.hex(" ")} '
                              '(the script has ended)')
        step = self.script.pop(0)
        if data != step.expect:
            raise ScriptError(f'{self.path}: sent {data.hex(" ")}, the script expects '
                              f'{step.expect.hex(" ")}')
        return step.reply, step.after_s

    def _take(self, n):
        taken, self._incoming = self._incoming[:n], self._incoming[n:]
        return bytes(b for _, b in taken)
