"""
Exceptions of the coil driver: one root, a few specific kinds.

The line's failures and bad configuration are tentacle_common's (every driver shares
them) and are re-exported here; CoilsError and the common ones share DriverError as root.
"""

from tentacle_common.errors import (  # noqa: F401 (re-exported)
    ConfigError, DriverError, ExchangeFailed, FrameError, LinkLost, Refused, ReplyTimeout,
    Superseded)


class CoilsError(DriverError):
    """Root of the errors only the coil driver raises."""


class CommandRejected(CoilsError):
    """A field or current command failed validation and was not sent."""


class NakError(CoilsError, Refused):
    """The device answered a set command with NAK."""


class SupplyFault(CoilsError, ExchangeFailed):
    """A command still failed after its bounded retries."""
