"""
Wire codec of the reference rig's own inserter (dialect ``step1mm``), from public lab code.

9600 baud, one ASCII character per 1 mm move, no reply and no position readback: the
position is counted, never measured. The lab's code has used two mappings: its later version
sends '2' to extend, '1' to retract and '3' to stop (the default here); an earlier one sent
'1' to extend and '2' to retract. Taken from public code, not a manual: a lab checks its
firmware before use.
"""

from dataclasses import dataclass

from tentacle_common.errors import ConfigError, FrameError

STEP_M = 1e-3  # one character, one move of this length
BAUD = 9600


@dataclass(frozen=True)
class Mapping:
    """The characters of the three commands (one ASCII byte each)."""

    extend: str = '2'
    retract: str = '1'
    stop: str = '3'

    def __post_init__(self):
        chars = (self.extend, self.retract, self.stop)
        if any(len(c) != 1 or not c.isascii() or not c.isprintable() for c in chars):
            raise ConfigError(f'step1mm characters must be single printable ASCII characters, '
                              f'got {chars!r}')
        if len(set(chars)) != 3:
            raise ConfigError(f'step1mm characters must differ, got {chars!r}')

    def command(self, direction):
        """Return the byte for direction +1 (extend), -1 (retract) or 0 (stop)."""
        return {1: self.extend, -1: self.retract, 0: self.stop}[direction].encode('ascii')

    def parse(self, raw):
        """
        Return the direction of one received byte: +1 extend, -1 retract, 0 stop.

        :raises FrameError: any other byte
        """
        text = bytes(raw).decode('ascii', errors='replace')
        for direction, char in ((1, self.extend), (-1, self.retract), (0, self.stop)):
            if text == char:
                return direction
        raise FrameError(f'not a step1mm command: {bytes(raw)!r}')


EARLIER = Mapping(extend='1', retract='2', stop='3')
