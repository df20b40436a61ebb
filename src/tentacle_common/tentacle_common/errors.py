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
