"""Byte-exact tests of the SCPI supply codec."""

import pytest

from tentacle_coils import scpi
from tentacle_coils.errors import FrameError


@pytest.mark.parametrize('line, expected', [
    (scpi.identify(), b'*IDN?\n'),
    (scpi.set_output(True), b'OUTP ON\n'),
    (scpi.set_output(False), b'OUTP OFF\n'),
    (scpi.set_current(1.5), b'CURR 1.5000\n'),
    (scpi.set_current(-12.34567), b'CURR -12.3457\n'),
    (scpi.set_current(-0.00001), b'CURR 0.0000\n'),
    (scpi.query_setpoint(), b'CURR?\n'),
    (scpi.measure_current(), b'MEAS:CURR?\n'),
    (scpi.measure_voltage(), b'MEAS:VOLT?\n'),
    (scpi.query_error(), b'SYST:ERR?\n'),
    (scpi.query_output(), b'OUTP?\n'),
])
def test_commands_are_byte_exact(line, expected):
    assert line == expected


def test_non_finite_current_raises():
    with pytest.raises(ValueError, match='not finite'):
        scpi.set_current(float('nan'))


def test_replies_parse_with_cr_tolerated():
    assert scpi.parse_float(b'-1.2500\r\n') == -1.25
    assert scpi.parse_bool(b'1\n') is True
    assert scpi.parse_error(b'0,"No error"\n') == (0, 'No error')
    assert scpi.parse_error(b'-222,"Data out of range"\r\n') == (-222, 'Data out of range')
    assert scpi.parse_identity(b'ACME,BPS-30,0042,1.3\n') == ('ACME', 'BPS-30', '0042', '1.3')


@pytest.mark.parametrize('parse, line', [
    (scpi.parse_float, b'1.2.3\n'), (scpi.parse_float, b'nan\n'), (scpi.parse_float, b'\xff\n'),
    (scpi.parse_bool, b'2\n'), (scpi.parse_error, b'-113 Undefined\n'),
    (scpi.parse_identity, b'ACME,BPS\n')])
def test_garbled_replies_raise(parse, line):
    with pytest.raises(FrameError):
        parse(line)


def test_parse_command_for_emulators():
    assert scpi.parse_command(b'curr -1.5\r\n') == ('CURR', '-1.5', False)
    assert scpi.parse_command(b'MEAS:CURR?\n') == ('MEAS:CURR?', None, True)
    with pytest.raises(FrameError, match='-113'):
        scpi.parse_command(b'VOLT 3\n')
    with pytest.raises(FrameError, match='-222'):
        scpi.parse_command(b'CURR\n')


def test_emulator_formats_round_trip():
    assert scpi.parse_error(scpi.format_error(-222, 'Data out of range')) == (
        -222, 'Data out of range')
    assert scpi.parse_float(scpi.format_value(-3.14159)) == pytest.approx(-3.1416)
