"""Exceptions of the coil driver: one root, a few specific kinds."""


class CoilsError(Exception):
    """Root of every error raised by tentacle_coils."""


class ConfigError(CoilsError):
    """A configuration value is missing, malformed or out of range."""


class CommandRejected(CoilsError):
    """A field or current command failed validation and was not sent."""


class FrameError(CoilsError):
    """Bytes on the wire do not form a valid frame or reply (garbled, bad checksum)."""


class NakError(CoilsError):
    """The device answered a set command with NAK."""


class ReplyTimeout(CoilsError):
    """No complete reply arrived before the deadline."""


class LinkLost(CoilsError):
    """The serial line is gone (device unplugged, port closed, I/O error)."""


class SupplyFault(CoilsError):
    """A command still failed after its bounded retries."""
