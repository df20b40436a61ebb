"""The stage dialects' codecs: bytes as DESIGN.md gives them, and back."""

import pytest
from tentacle_common.errors import ConfigError, FrameError
from tentacle_inserter import gcode, step1mm


def test_gcode_commands_are_the_design_lines():
    assert gcode.absolute() == b'G90\n' and gcode.relative() == b'G91\n'
    assert gcode.move(0.0125, 0.005) == b'G1 E12.5000 F300.00\n'   # 5 mm/s = 300 mm/min
    assert gcode.set_position(0.0) == b'G92 E0.0000\n'
    assert gcode.wait_for_motion() == b'M400\n' and gcode.report_position() == b'M114\n'
    assert gcode.steps_per_mm(93.0) == b'M92 E93.00000\n'
    assert (gcode.motor_off(), gcode.halt(), gcode.reset()) == (b'M18\n', b'M112\n', b'M999\n')


@pytest.mark.parametrize('bad', [float('nan'), float('inf')])
def test_gcode_refuses_a_non_finite_target_before_it_is_bytes(bad):
    with pytest.raises(ValueError, match='not finite'):
        gcode.move(bad, 0.005)
    with pytest.raises(ValueError, match='not positive'):
        gcode.move(0.01, 0.0)


def test_gcode_commands_parse_back():
    assert gcode.parse_command(gcode.move(0.0125, 0.005)) == ('G1', {'E': 12.5, 'F': 300.0})
    assert gcode.parse_command(b'g92 e-1.5 ; park\r\n') == ('G92', {'E': -1.5})
    for bad in (b'G1 X3\n', b'G1 E1 E2\n', b'G28\n', b'G1 Eabc\n', b'\xff\n', b'\n'):
        with pytest.raises(FrameError):
            gcode.parse_command(bad)


def test_gcode_replies_parse():
    assert gcode.parse_reply(b'ok\n') == ('ok', None)
    assert gcode.parse_reply(gcode.format_error('Printer halted. kill() called!')) == (
        'error', 'Printer halted. kill() called!')
    kind, position = gcode.parse_reply(gcode.format_position(12.34))
    assert kind == 'position' and position == pytest.approx(0.01234)
    assert gcode.parse_reply(b'start\n') == ('start', None)
    assert gcode.parse_reply(b'echo:busy: processing\n') == ('other', 'echo:busy: processing')


def test_step1mm_mappings():
    later = step1mm.Mapping()
    assert [later.command(d) for d in (1, -1, 0)] == [b'2', b'1', b'3']
    assert [step1mm.EARLIER.command(d) for d in (1, -1)] == [b'1', b'2']
    assert later.parse(b'2') == 1 and later.parse(b'1') == -1 and later.parse(b'3') == 0
    with pytest.raises(FrameError):
        later.parse(b'x')
    with pytest.raises(ConfigError, match='must differ'):
        step1mm.Mapping(extend='1', retract='1')
    with pytest.raises(ConfigError, match='single printable'):
        step1mm.Mapping(stop='\n')
