"""The axis drivers against the stage emulators over real ptys: the wire and the truth."""

import time

import pytest
from tentacle_common.serial_line import SerialLine
from tentacle_inserter import stage
from tentacle_inserter.trapezoid import move_time_s
from tentacle_sim import stage_emulator

SPEED, ACCEL, STEPS_PER_MM = 0.01, 0.5, 80.0
STEP_M = 1e-3 / STEPS_PER_MM


@pytest.fixture
def rig(tmp_path):
    made = []

    def make(kind='gcode', **kwargs):
        link = str(tmp_path / 'stage')
        if kind == 'gcode':
            emu = stage_emulator.GcodeStage('e', link_path=link, accel_m_s2=ACCEL,
                                            steps_per_mm=10.0).start()
            axis = stage.GcodeStage(SerialLine(link, 115200), max_length_m=0.05,
                                    max_speed_m_s=SPEED, accel_m_s2=ACCEL,
                                    steps_per_mm=STEPS_PER_MM, reply_timeout_s=0.2, **kwargs)
        else:
            emu = stage_emulator.Step1mmStage('e', link_path=link, speed_m_s=SPEED).start()
            axis = stage.Step1mmStage(SerialLine(link, 9600), max_length_m=0.05)
        made.append((emu, axis))
        axis.connect()
        return emu, axis
    yield make
    for emu, axis in made:
        axis.line.close()
        emu.stop()


def sent(emu, command):
    return [e for e in emu.log if e.get('command') == command]


def test_connect_calibrates_and_a_move_needs_a_home_first(rig):
    emu, axis = rig()
    assert emu.state()['steps_per_mm'] == STEPS_PER_MM        # M92 at connect
    with pytest.raises(stage.NotHomed):
        axis.move_to(0.005)
    assert sent(emu, 'G1') == []                              # nothing reached the wire
    assert axis.home() == 0.0 and axis.homed


def test_a_move_ends_where_the_device_says_within_one_step(rig):
    emu, axis = rig()
    axis.home()
    t0 = time.monotonic()
    position = axis.move_to(0.0123456)
    took = time.monotonic() - t0
    truth = emu.state()
    assert abs(truth['position_m'] - 0.0123456) <= STEP_M / 2 + 1e-12
    assert position == pytest.approx(truth['position_m'], abs=1e-5)   # M114's 0.01 mm
    assert not truth['busy']
    assert took >= move_time_s(0.0123456, SPEED, ACCEL) - 0.02


@pytest.mark.parametrize('target, why', [(float('nan'), 'not finite'),
                                         (float('inf'), 'not finite'),
                                         (-0.001, 'outside'), (0.051, 'outside'),
                                         ('5 mm', 'not a number')])
def test_bad_targets_never_reach_the_wire(rig, target, why):
    emu, axis = rig()
    axis.home()
    with pytest.raises(stage.TargetRefused, match=why):
        axis.move_to(target)
    assert sent(emu, 'G1') == []


def test_a_stall_is_caught_in_time_and_the_axis_stopped(rig):
    emu, axis = rig(time_margin=1.2, slack_s=0.3)
    axis.home()
    emu.inject('stall', after_m=0.002)
    allowed = move_time_s(0.02, SPEED, ACCEL) * 1.2 + 0.3
    t0 = time.monotonic()
    with pytest.raises(stage.MoveFailed, match='did not finish'):
        axis.move_to(0.02)
    assert time.monotonic() - t0 < allowed + 1.5        # the wait, then M112, M999, M114
    truth = emu.state()
    assert not truth['busy'] and not truth['moving'] and truth['position_m'] < 0.005
    assert sent(emu, 'M112') and not axis.homed
    with pytest.raises(stage.NotHomed):                 # never replayed, never assumed
        axis.move_to(0.02)


def test_a_lost_ok_is_retried_without_moving_twice(rig):
    emu, axis = rig()
    axis.home()
    emu.inject('drop_reply', count=1)
    axis.move_to(0.004)                                  # the G1 is re-sent: absolute
    assert len(sent(emu, 'G1')) == 2
    assert abs(emu.state()['position_m'] - 0.004) <= STEP_M / 2 + 1e-12


def test_step1mm_counts_what_it_sent(rig):
    emu, axis = rig('step1mm')
    assert not axis.measured
    axis.home()
    with pytest.raises(stage.TargetRefused, match='resolution'):
        axis.move_to(0.0032)                                  # whole millimetres only
    assert axis.move_to(0.003) == pytest.approx(0.003)
    time.sleep(3 * move_time_s(0.001, SPEED, 0.5) + 0.3)
    assert emu.state()['position_m'] == pytest.approx(0.003)
    assert axis.move_to(0.001) == pytest.approx(0.001)
    time.sleep(2 * move_time_s(0.001, SPEED, 0.5) + 0.3)
    assert emu.state()['position_m'] == pytest.approx(0.001)
    with pytest.raises(stage.TargetRefused):
        axis.move_to(float('nan'))
    assert [e['command'] for e in emu.log] == ['stop'] + ['extend'] * 3 + ['retract'] * 2


def test_the_gcode_driver_on_a_step1mm_stage_moves_nothing(tmp_path):
    link = str(tmp_path / 'stage')
    emu = stage_emulator.Step1mmStage('e', link_path=link, speed_m_s=SPEED).start()
    axis = stage.GcodeStage(SerialLine(link, 115200), max_length_m=0.05, max_speed_m_s=SPEED,
                            accel_m_s2=ACCEL, steps_per_mm=STEPS_PER_MM, reply_timeout_s=0.2,
                            restart_timeout_s=0.5)
    try:
        with pytest.raises(stage.NeverAnswered, match='step1mm'):
            axis.connect()
        with pytest.raises(stage.NeverAnswered):
            axis.stop()
    finally:
        axis.line.close()
        emu.stop()
    assert emu.state()['position_m'] == 0.0 and not emu.state()['busy']
    assert [bytes.fromhex(e['hex']) for e in emu.log] == [b'G', b'9', b'0', b'\n']
