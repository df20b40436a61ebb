"""
Wire codec of a generic SCPI bipolar supply (one per axis, text lines, 8N1).

Lines end in LF (CR tolerated on input). Set commands get no reply; queries get one line.
Commands are declared as data below; the driver (supply.py) and the emulator
(tentacle_sim) share them.
"""

import math
import re

from tentacle_coils.errors import FrameError

TERMINATOR = b'\n'

# Header -> (takes a numeric argument, is a query). Only what the dialect defines.
COMMANDS = {
    '*IDN?': (False, True),
    'OUTP': (True, False),       # argument ON / OFF
    'OUTP?': (False, True),
    'CURR': (True, False),       # argument amperes
    'CURR?': (False, True),
    'MEAS:CURR?': (False, True),
    'MEAS:VOLT?': (False, True),
    'SYST:ERR?': (False, True),
}

NO_ERROR = (0, 'No error')
UNDEFINED_HEADER = (-113, 'Undefined header')
DATA_OUT_OF_RANGE = (-222, 'Data out of range')

_ERROR_RE = re.compile(r'^\s*([+-]?\d+)\s*,\s*"(.*)"\s*$')


def _line(text):
    return text.encode('ascii') + TERMINATOR


def identify():
    """Return the ``*IDN?`` query."""
    return _line('*IDN?')


def set_output(on):
    """Return ``OUTP ON`` or ``OUTP OFF``."""
    return _line('OUTP ON' if on else 'OUTP OFF')


def query_output():
    """Return the ``OUTP?`` query."""
    return _line('OUTP?')


def set_current(current_a):
    """
    Return ``CURR <amps>`` with 0.1 mA resolution.

    :raises ValueError: a current that is not finite
    """
    if not math.isfinite(current_a):
        raise ValueError(f'scpi current {current_a} A is not finite')
    text = f'{current_a:.4f}'
    if text in ('-0.0000',):
        text = '0.0000'
    return _line(f'CURR {text}')


def query_setpoint():
    """Return the ``CURR?`` query."""
    return _line('CURR?')


def measure_current():
    """Return the ``MEAS:CURR?`` query."""
    return _line('MEAS:CURR?')


def measure_voltage():
    """Return the ``MEAS:VOLT?`` query."""
    return _line('MEAS:VOLT?')


def query_error():
    """Return the ``SYST:ERR?`` query."""
    return _line('SYST:ERR?')


def _text(line):
    if isinstance(line, (bytes, bytearray)):
        try:
            line = bytes(line).decode('ascii')
        except UnicodeDecodeError:
            raise FrameError(f'scpi reply {bytes(line)!r} is not ASCII') from None
    return line.strip('\r\n ')


def parse_float(line):
    """
    Return the number in a reply line.

    :raises FrameError: not one finite number
    """
    text = _text(line)
    try:
        value = float(text)
    except ValueError:
        raise FrameError(f'scpi reply {text!r} is not a number') from None
    if not math.isfinite(value):
        raise FrameError(f'scpi reply {text!r} is not finite')
    return value


def parse_bool(line):
    """
    Return the state in an ``OUTP?`` reply (``1`` or ``0``).

    :raises FrameError: anything else
    """
    text = _text(line)
    if text not in ('0', '1'):
        raise FrameError(f'scpi reply {text!r} is not 0 or 1')
    return text == '1'


def parse_error(line):
    """
    Return (code, text) of a ``SYST:ERR?`` reply; code 0 means no error.

    :raises FrameError: not of the form ``<code>,"<text>"``
    """
    text = _text(line)
    match = _ERROR_RE.match(text)
    if not match:
        raise FrameError(f'scpi error reply {text!r} is not <code>,"<text>"')
    return int(match.group(1)), match.group(2)


def parse_identity(line):
    """
    Return (maker, model, serial, firmware) of an ``*IDN?`` reply.

    :raises FrameError: not four comma-separated fields
    """
    fields = [f.strip() for f in _text(line).split(',')]
    if len(fields) != 4 or not fields[0]:
        raise FrameError(f'scpi identity {_text(line)!r} is not maker,model,serial,firmware')
    return tuple(fields)


def format_error(code, text):
    """Return a device's ``SYST:ERR?`` reply line (used by emulators)."""
    return _line(f'{code},"{text}"')


def format_value(value):
    """Return a device's numeric reply line (used by emulators)."""
    return _line(f'{value:.4f}')


def parse_command(line):
    """
    Split a received command line into (header, argument or None, is_query).

    Headers are case-insensitive, as SCPI allows.

    :raises FrameError: an undefined header, a missing or surplus argument (code -113 or -222
        is in the message so an emulator can queue it)
    """
    text = _text(line)
    header, _, argument = text.partition(' ')
    header = header.upper()
    argument = argument.strip() or None
    if header not in COMMANDS:
        raise FrameError(f'scpi {UNDEFINED_HEADER[0]} undefined header {header!r}')
    takes_argument, is_query = COMMANDS[header]
    if takes_argument != (argument is not None):
        raise FrameError(f'scpi {DATA_OUT_OF_RANGE[0]} {header} '
                         f'{"needs" if takes_argument else "takes no"} argument')
    return header, argument, is_query
