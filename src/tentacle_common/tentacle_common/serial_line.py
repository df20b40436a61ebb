"""
A serial line opened by path, with deadline-bounded reads and line-rate paced writes.

The same class serves a USB-RS232 adapter and a pseudo-terminal; only the path differs.
"""

import os
import select
import time

import serial

from tentacle_common.errors import FrameError, LinkLost, ReplyTimeout

BITS_PER_BYTE = 10  # 8N1: start, 8 data, stop
WRITE_TIMEOUT_S = 1.0  # a write that cannot go out this long means the line is gone


class SerialLine:
    """
    One serial port.

    Reads take an absolute deadline (``now()`` seconds) and raise ReplyTimeout past it.
    Writes are paced at ``baud`` with at most one write queued behind the one on the line:
    commands that get no reply keep the line busy but never queue up stale ones. Any I/O
    failure raises LinkLost and closes the port. Drivers take every time from ``now()``, so
    a scripted line with a virtual clock (tentacle_common.scripted_line) can stand in for it.
    """

    def __init__(self, path, baud):
        """Remember where and how fast; ``open()`` connects."""
        self.path = path
        self.baud = int(baud)
        self._port = None
        self._rx = bytearray()
        self._tx_free_at = 0.0

    def now(self):
        """Return the line's clock (s): ``time.monotonic()``."""
        return time.monotonic()

    @property
    def tx_free_at(self):
        """Return when the last byte written so far leaves the line (``now()`` seconds)."""
        return self._tx_free_at

    def wire_time_s(self, n_bytes):
        """Return the time n_bytes take on the line (s)."""
        return n_bytes * BITS_PER_BYTE / self.baud

    @property
    def is_open(self):
        """Return True while the port is open."""
        return self._port is not None

    def open(self):  # noqa: A003 (the serial-port verb, as in pyserial)
        """
        Open the port (8N1, exclusive).

        :raises LinkLost: the path does not exist or cannot be opened
        """
        self.close()
        try:
            self._port = serial.Serial(self.path, self.baud, timeout=0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkLost(f'cannot open {self.path}: {exc}') from None
        self._rx.clear()
        self._tx_free_at = 0.0

    def close(self):
        """Close the port; safe to call twice."""
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError):
                pass

    def _require(self):
        if self._port is None:
            raise LinkLost(f'{self.path} is not open')
        return self._port

    def _lost(self, exc):
        self.close()
        return LinkLost(f'{self.path}: {exc}')

    def write(self, data):
        """
        Send bytes once the previous write has left the line.

        :return: when the last of these bytes leaves the line (``now()`` seconds)
        :raises LinkLost: the port failed
        """
        fd = self._require().fileno()
        wire_s = self.wire_time_s(len(data))
        # Go when at most this write's own length is still queued ahead of it: the line never
        # idles between commands, and a command never waits behind more than one other.
        wait = self._tx_free_at - wire_s - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        # os.write on the (non-blocking) descriptor: pyserial's write costs several times
        # more interpreter time per command, which the other supplies' threads wait for.
        view = memoryview(data)
        deadline = time.monotonic() + WRITE_TIMEOUT_S
        try:
            while view:
                try:
                    view = view[os.write(fd, view):]
                except BlockingIOError:
                    remaining = deadline - time.monotonic()
                    if remaining <= 0 or not select.select([], [fd], [], remaining)[1]:
                        raise self._lost(f'write blocked for {WRITE_TIMEOUT_S} s') from None
        except OSError as exc:
            raise self._lost(exc) from None
        self._tx_free_at = max(time.monotonic(), self._tx_free_at) + wire_s
        return self._tx_free_at

    def _fill(self, deadline):
        """Wait until more bytes arrive or the deadline passes; return False on timeout."""
        port = self._require()
        remaining = max(0.0, deadline - time.monotonic())  # 0: poll once
        try:
            readable, _, _ = select.select([port.fileno()], [], [], remaining)
            if not readable:
                return False
            chunk = os.read(port.fileno(), 4096)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise self._lost(exc) from None
        if not chunk:
            raise self._lost('end of file (device gone)')
        self._rx += chunk
        return True

    def read_exact(self, n_bytes, deadline):
        """
        Return exactly n_bytes.

        :raises ReplyTimeout: fewer arrived by the deadline (the partial bytes are dropped)
        :raises LinkLost: the port failed
        """
        while len(self._rx) < n_bytes:
            if not self._fill(deadline):
                got, self._rx = bytes(self._rx), bytearray()
                raise ReplyTimeout(f'{self.path}: {len(got)} of {n_bytes} bytes by the deadline'
                                   + (f' ({got.hex(" ")})' if got else ''))
        out = bytes(self._rx[:n_bytes])
        del self._rx[:n_bytes]
        return out

    def wait_input(self, deadline):
        """
        Return True once input is buffered (none of it taken), False at the deadline.

        :raises LinkLost: the port failed
        """
        return bool(self._rx) or self._fill(deadline)

    def read_until(self, terminator, deadline, max_bytes=256):
        """
        Return the bytes up to and including terminator.

        :raises ReplyTimeout: no terminator by the deadline, or more than max_bytes without one
        :raises LinkLost: the port failed
        """
        while True:
            end = self._rx.find(terminator)
            if end >= 0:
                end += len(terminator)
                out = bytes(self._rx[:end])
                del self._rx[:end]
                return out
            if len(self._rx) > max_bytes or not self._fill(deadline):
                got, self._rx = bytes(self._rx), bytearray()
                raise ReplyTimeout(f'{self.path}: no complete line by the deadline'
                                   + (f' (got {got[:40]!r})' if got else ''))

    def discard_input(self, quiet_s=0.0, max_s=5.0):
        """
        Drop buffered and pending input; with quiet_s, until the line is quiet that long.

        :param quiet_s: how long no byte may arrive before the line counts as quiet (s)
        :param max_s: give up on a line that never goes quiet after this long (s)
        :return: the number of bytes dropped
        :raises FrameError: the line was not quiet for quiet_s within max_s (babbling)
        :raises LinkLost: the port failed
        """
        dropped = len(self._rx)
        self._rx.clear()
        give_up = time.monotonic() + max_s
        while self._fill(time.monotonic() + quiet_s):
            dropped += len(self._rx)
            self._rx.clear()
            if time.monotonic() > give_up:
                raise FrameError(f'{self.path}: still receiving after {max_s:g} s '
                                 f'({dropped} bytes dropped)')
        return dropped
