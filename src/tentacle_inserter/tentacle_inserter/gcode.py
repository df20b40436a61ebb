"""
Wire codec of a Marlin-style stage (DESIGN.md, dialect ``gcode``): the axis is E, in mm.

Lines end in LF (CR tolerated). Every command is answered ``ok`` once queued; ``M400`` only
once motion has finished; ``M114`` answers a position line, then ``ok``; a failure answers
``Error:<text>``; a firmware that has (re)started says ``start``. Commands are declared as
data below, so the driver and the emulator (tentacle_sim.stage_emulator) share one
definition of the wire. Units: metres and m/s on this side, mm and mm/min on the wire.
"""

import math
import re

from tentacle_common.errors import FrameError

TERMINATOR = b'\n'
OK = b'ok\n'
START = b'start\n'
HALTED = 'Printer halted. kill() called!'  # what Marlin answers after M112 until a reset

# Code -> (letters it takes, what it does). Only what the dialect defines.
COMMANDS = {
    'G90': ('', 'absolute positioning'),
    'G91': ('', 'relative positioning'),
    'G92': ('E', 'set the position (mm)'),
    'G1': ('EF', 'move: E position (mm), F speed (mm/min)'),
    'M400': ('', 'answer ok when motion has finished'),
    'M114': ('', 'report the position'),
    'M92': ('E', 'steps per mm'),
    'M18': ('', 'disable the motor'),
    'M112': ('', 'emergency halt, until reset'),
    'M999': ('', 'reset after a halt'),
}

_WORD = re.compile(r'^([A-Z])([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)$')
_POSITION = re.compile(r'\bE:\s*([-+]?\d+(?:\.\d*)?)')


def _line(text):
    return text.encode('ascii') + TERMINATOR


def _mm(metres, what):
    if not math.isfinite(metres):
        raise ValueError(f'{what} {metres!r} is not finite')
    return metres * 1e3


def absolute():
    """Return ``G90``."""
    return _line('G90')


def relative():
    """Return ``G91``."""
    return _line('G91')


def set_position(position_m):
    """Return ``G92 E<mm>``: the current position is called position_m (m)."""
    return _line(f'G92 E{_mm(position_m, "position"):.4f}')


def move(position_m, speed_m_s):
    """Return ``G1 E<mm> F<mm/min>``: move to position_m (m) at up to speed_m_s (m/s)."""
    speed = _mm(speed_m_s, 'speed') * 60.0
    if not speed > 0:
        raise ValueError(f'speed {speed_m_s!r} m/s is not positive')
    return _line(f'G1 E{_mm(position_m, "position"):.4f} F{speed:.2f}')


def wait_for_motion():
    """Return ``M400``."""
    return _line('M400')


def report_position():
    """Return ``M114``."""
    return _line('M114')


def steps_per_mm(steps):
    """Return ``M92 E<steps/mm>``."""
    if not (math.isfinite(steps) and steps > 0):
        raise ValueError(f'steps per mm {steps!r} is not a positive number')
    return _line(f'M92 E{steps:.5f}')


def motor_off():
    """Return ``M18``."""
    return _line('M18')


def halt():
    """Return ``M112``."""
    return _line('M112')


def reset():
    """Return ``M999``."""
    return _line('M999')


def parse_command(raw):
    """
    Return (code, {letter: value}) of a command line, values as on the wire (mm, mm/min).

    :raises FrameError: not ASCII, an unknown code, a letter the code does not take, a
        malformed number or a letter given twice
    """
    try:
        text = raw.decode('ascii').strip()
    except UnicodeDecodeError:
        raise FrameError(f'not ASCII: {raw!r}') from None
    text = text.split(';', 1)[0].strip().upper()  # a comment runs to the end of the line
    words = text.split()
    if not words or words[0] not in COMMANDS:
        raise FrameError(f'unknown command: {text!r}')
    code, letters = words[0], COMMANDS[words[0]][0]
    values = {}
    for word in words[1:]:
        match = _WORD.match(word)
        if not match or match.group(1) not in letters or match.group(1) in values:
            raise FrameError(f'{code}: bad word {word!r}')
        values[match.group(1)] = float(match.group(2))
    return code, values


def format_position(position_mm):
    """Return the ``M114`` answer's position line for E at position_mm (mm)."""
    return _line(f'X:0.00 Y:0.00 Z:0.00 E:{position_mm:.2f} Count X:0 Y:0 Z:0')


def format_error(text):
    """Return an ``Error:`` line."""
    return _line(f'Error:{text}')


def parse_reply(raw):
    """
    Return (kind, value) of a reply line.

    ('ok', None); ('error', text); ('position', E in m) from an M114 line; ('start', None)
    from a firmware that has just (re)started; ('other', text) for anything else a firmware
    prints (echo lines, busy notices).

    :raises FrameError: not ASCII
    """
    try:
        text = raw.decode('ascii').strip()
    except UnicodeDecodeError:
        raise FrameError(f'not ASCII: {raw!r}') from None
    if text == 'ok' or text.startswith('ok '):
        return 'ok', None
    if text.startswith('Error:'):
        return 'error', text[len('Error:'):].strip()
    if text == 'start':
        return 'start', None
    position = _POSITION.search(text)
    if position and text.startswith('X:'):
        return 'position', float(position.group(1)) * 1e-3
    return 'other', text
