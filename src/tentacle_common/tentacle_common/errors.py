"""Exceptions every driver shares: one root, the line's failures, bad configuration."""


class DriverError(Exception):
    """Root of the errors raised by tentacle_common and the drivers built on it."""


class ConfigError(DriverError):
    """A configuration value is missing, malformed or out of range."""


class FrameError(DriverError):
    """Bytes on the wire do not form a valid frame or reply (garbled, bad checksum)."""


class Refused(DriverError):
    """The device answered, and refused the request (a NAK, an error reply)."""


class ReplyTimeout(DriverError):
    """No complete reply arrived before the deadline."""


class LinkLost(DriverError):
    """The serial line is gone (device unplugged, port closed, I/O error)."""


class ExchangeFailed(DriverError):
    """A request still failed after its bounded retries."""


class Superseded(DriverError):
    """
    A request was dropped before an attempt because its value is no longer wanted.

    ``ambiguous``: an earlier attempt went unanswered, so the device may hold the value
    anyway: read it back before planning again.
    """

    def __init__(self, message, ambiguous=False):
        """Say what was dropped and whether the device may have taken it."""
        super().__init__(message)
        self.ambiguous = ambiguous
