"""The stage emulators from the wire: gcode and step1mm firmware over real ptys."""

import os
import select
import time

import pytest
from tentacle_inserter import gcode
from tentacle_inserter.trapezoid import move_time_s
from tentacle_sim.stage_emulator import GcodeStage, Step1mmStage

ACCEL = 0.5


def read_line(fd, timeout_s=1.0):
    out, deadline = b'', time.monotonic() + timeout_s
    while not out.endswith(b'\n') and time.monotonic() < deadline:
        if select.select([fd], [], [], max(deadline - time.monotonic(), 0))[0]:
            out += os.read(fd, 1)
    return out


def ask(fd, line, timeout_s=1.0):
    os.write(fd, line)
    return read_line(fd, timeout_s)


@pytest.fixture
def stage(on_pty):
    return lambda kind=GcodeStage, **kwargs: on_pty(kind, 'e', **kwargs)


def test_a_move_is_queued_at_once_and_finished_on_the_trapezoid(stage):
    dev, fd = stage(accel_m_s2=ACCEL, steps_per_mm=80.0)
    assert ask(fd, gcode.move(0.0100037, 0.01)) == b'ok\n'      # queued: ok at once
    t0 = time.monotonic()
    assert dev.state()['moving']
    assert ask(fd, gcode.wait_for_motion(), 3.0) == b'ok\n'
    took = time.monotonic() - t0
    expected = move_time_s(0.010, 0.01, ACCEL)
    assert expected - 0.02 <= took <= expected + 0.1
    # To whole steps: 80 steps a mm, so 10.0037 mm is step 800, 10.000 mm.
    assert dev.state()['position_m'] == pytest.approx(0.010, abs=1e-12)
    os.write(fd, gcode.report_position())
    assert gcode.parse_reply(read_line(fd)) == ('position', pytest.approx(0.010))
    assert read_line(fd) == b'ok\n'


def test_relative_moves_and_a_set_position(stage):
    dev, fd = stage(accel_m_s2=5.0)
    assert ask(fd, gcode.set_position(0.002)) == b'ok\n'
    assert ask(fd, gcode.relative()) == b'ok\n'
    for _ in range(3):
        assert ask(fd, gcode.move(0.001, 0.02)) == b'ok\n'
    assert ask(fd, gcode.wait_for_motion(), 2.0) == b'ok\n'
    assert dev.state()['position_m'] == pytest.approx(0.005)


def test_m112_stops_at_once_and_holds_until_reset(stage):
    dev, fd = stage(accel_m_s2=ACCEL)
    ask(fd, gcode.move(0.02, 0.01))
    time.sleep(0.5)
    os.write(fd, gcode.halt())
    time.sleep(0.05)
    halted = dev.state()
    assert halted['halted'] and not halted['busy'] and 0.001 < halted['position_m'] < 0.01
    assert gcode.parse_reply(ask(fd, gcode.move(0.03, 0.01))) == ('error', gcode.HALTED)
    time.sleep(0.2)
    assert dev.state()['position_m'] == halted['position_m']        # nothing moved
    assert ask(fd, gcode.reset()) == b'ok\n'                      # M999: running again,
    assert dev.state()['position_m'] == halted['position_m']        # its count kept
    assert not dev.state()['halted']


def test_a_firmware_that_must_restart_after_a_halt_refuses_m999_then_says_start(stage):
    dev, fd = stage(reset_after_halt_s=0.2)
    ask(fd, gcode.move(0.002, 0.01))
    time.sleep(0.3)
    os.write(fd, gcode.halt())
    assert gcode.parse_reply(ask(fd, gcode.reset())) == ('error', gcode.HALTED)  # no M999
    assert read_line(fd, 1.0) == b'start\n'
    stood = dev.state()['travel_m']
    assert stood > 0.0005 and dev.state()['position_m'] == 0.0  # counts from 0 where it stands
    assert ask(fd, gcode.move(0.001, 0.01)) == b'ok\n'
    time.sleep(0.5)
    assert dev.state()['travel_m'] == pytest.approx(stood + 0.001, abs=1e-5)


def test_a_stall_stops_the_axis_and_m400_never_answers(stage):
    dev, fd = stage(accel_m_s2=ACCEL)
    ask(fd, gcode.move(0.02, 0.01))
    dev.inject('stall', after_m=0.002)
    assert ask(fd, gcode.wait_for_motion(), move_time_s(0.02, 0.01, ACCEL) + 0.5) == b''
    truth = dev.state()
    # The axis stands still while the firmware's move never ends.
    assert truth['stalled'] and not truth['moving'] and truth['busy']
    assert truth['position_m'] < 0.01


def test_a_lost_ok_and_a_restart_now(stage):
    dev, fd = stage(accel_m_s2=5.0)
    dev.inject('drop_reply')
    assert ask(fd, gcode.move(0.001, 0.02), 0.3) == b''        # obeyed, ok lost
    time.sleep(0.3)
    assert dev.state()['position_m'] == pytest.approx(0.001)
    dev.inject('reset')
    assert read_line(fd) == b'start\n' and dev.state()['position_m'] == 0.0
    assert dev.state()['travel_m'] == pytest.approx(0.001)             # the axis did not move
    assert dev.log[0]['fault'] == 'drop_reply'


def test_slow_moves_take_longer(stage):
    dev, fd = stage(accel_m_s2=5.0)
    dev.inject('slow', factor=0.5)
    ask(fd, gcode.move(0.005, 0.02))
    t0 = time.monotonic()
    assert ask(fd, gcode.wait_for_motion(), 2.0) == b'ok\n'
    assert time.monotonic() - t0 >= 0.9 * move_time_s(0.005, 0.01, 5.0)


def test_step1mm_moves_a_millimetre_a_character_and_never_answers(stage):
    dev, fd = stage(Step1mmStage, speed_m_s=0.01)
    os.write(fd, b'222')
    time.sleep(0.01)
    assert dev.state()['moving']
    time.sleep(3 * move_time_s(0.001, 0.01, 0.5) + 0.2)
    assert dev.state()['position_m'] == pytest.approx(0.003)
    os.write(fd, b'1')
    time.sleep(move_time_s(0.001, 0.01, 0.5) + 0.2)
    assert dev.state()['position_m'] == pytest.approx(0.002)
    os.write(fd, b'2223')                                       # stop: the rest is dropped
    time.sleep(0.5)
    assert 0.002 <= dev.state()['position_m'] < 0.005 and not dev.state()['busy']
    os.write(fd, b'x')
    time.sleep(0.05)
    assert 'error' in dev.log[-1]
    assert read_line(fd, 0.1) == b''
