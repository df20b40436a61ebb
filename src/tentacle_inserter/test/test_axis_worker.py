"""The axis worker against the gcode emulator: latest target, stop, estop, a lost line."""

import time

import pytest
from tentacle_common.serial_line import SerialLine
from tentacle_inserter import stage
from tentacle_inserter.axis_worker import AxisWorker
from tentacle_sim.stage_emulator import GcodeStage

SPEED, ACCEL = 0.01, 0.5


@pytest.fixture
def worker(tmp_path, wait_for):
    link = str(tmp_path / 'stage')
    emu = GcodeStage('e', link_path=link, accel_m_s2=ACCEL).start()
    axis = stage.GcodeStage(SerialLine(link, 115200), max_length_m=0.05, max_speed_m_s=SPEED,
                            accel_m_s2=ACCEL, steps_per_mm=100.0, reply_timeout_s=0.2)
    w = AxisWorker(axis, reconnect_s=0.2).start()
    assert wait_for(lambda: w.connected)
    assert w.home() == (True, 'zero is here')
    yield w, emu
    w.shutdown()
    emu.stop()


def targets_sent(emu):
    return [round(e['E'], 3) for e in emu.log if e.get('command') == 'G1']


def test_the_latest_target_wins_and_none_is_replayed(worker, wait_for):
    w, emu = worker
    w.set_target(0.010)
    assert wait_for(lambda: emu.state()['moving'])
    w.set_target(0.020)          # replaced before it started
    w.set_target(0.030)
    assert wait_for(lambda: w.moves == 2 and not w.snapshot()['moving'], 10.0)
    assert targets_sent(emu) == [10.0, 30.0]
    assert emu.state()['position_m'] == pytest.approx(0.030, abs=1e-5)
    assert w.snapshot()['position_m'] == pytest.approx(0.030, abs=1e-5)


def test_stop_cuts_a_move_short_at_once(worker, wait_for):
    w, emu = worker
    w.set_target(0.030)
    assert wait_for(lambda: emu.state()['moving'])
    t0 = time.monotonic()
    w.stop()
    assert wait_for(lambda: not emu.state()['moving'], 0.5)
    assert time.monotonic() - t0 < 0.1     # the worker's poll, then M112 on the line
    assert wait_for(lambda: 'stopped' in w.snapshot()['error'])
    assert not w.snapshot()['homed']
    assert emu.state()['travel_m'] < 0.03


def test_a_home_asked_for_right_after_a_stop_is_done(worker, wait_for):
    w, emu = worker
    w.set_target(0.030)
    assert wait_for(lambda: emu.state()['moving'])
    w.stop()
    t0 = time.monotonic()
    assert w.home(timeout_s=3.0) == (True, 'zero is here')   # not lost behind the stop
    assert time.monotonic() - t0 < 2.0
    assert w.snapshot()['homed'] and w.snapshot()['error'] == ''
    commands = [e['command'] for e in emu.log]
    assert commands[commands.index('G1'):].count('M112') == 1  # one stop, not two


def test_the_estop_halts_and_holds_until_released(worker, wait_for):
    w, emu = worker
    w.set_target(0.030)
    assert wait_for(lambda: emu.state()['moving'])
    w.set_estop(True)
    assert wait_for(lambda: not emu.state()['moving'], 0.5)
    with pytest.raises(stage.TargetRefused, match='estop active'):
        w.set_target(0.001)
    assert w.home() == (False, 'estop active')
    time.sleep(0.3)
    assert not emu.state()['moving'] and targets_sent(emu) == [30.0]
    w.set_estop(False)
    assert w.home()[0]
    w.set_target(0.001)
    assert wait_for(lambda: w.moves == 1)


def test_a_lost_line_reconnects_unhomed_and_replays_nothing(worker, wait_for):
    w, emu = worker
    emu.inject('disconnect', duration_s=0.5)
    assert wait_for(lambda: not emu.state()['connected'], 1.0)
    w.set_target(0.005)          # taken, then lost with the line
    assert wait_for(lambda: not w.connected, 2.0)
    assert wait_for(lambda: w.connected, 3.0)
    assert not w.snapshot()['homed']
    time.sleep(0.3)
    assert targets_sent(emu) == []


def test_state_during_a_move_follows_the_profile_and_says_so(worker, wait_for):
    w, emu = worker
    w.set_target(0.020)
    assert wait_for(lambda: emu.state()['moving'])
    for _ in range(5):
        time.sleep(0.2)
        snap, truth = w.snapshot(), emu.state()
        if not snap['moving']:
            break
        assert snap['estimated']
        assert snap['position_m'] == pytest.approx(truth['position_m'], abs=0.0005)
        assert snap['velocity_m_s'] == pytest.approx(truth['velocity_m_s'], abs=0.002)
    assert wait_for(lambda: not w.snapshot()['moving'], 5.0)
    assert not w.snapshot()['estimated']


def test_disable_stops_switches_the_motor_off_and_refuses_targets(worker, wait_for):
    w, emu = worker
    w.set_target(0.030)
    assert wait_for(lambda: emu.state()['moving'])
    w.set_enabled(False)
    assert wait_for(lambda: not emu.state()['motor_on'], 2.0)
    assert not emu.state()['moving']
    with pytest.raises(stage.TargetRefused, match='disabled'):
        w.set_target(0.001)
    w.set_enabled(True)
    assert w.home()[0]
    w.set_target(0.001)
    assert wait_for(lambda: w.moves == 1 and emu.state()['motor_on'], 5.0)


def test_the_status_says_what_holds_the_axis(worker, wait_for):
    w, emu = worker
    assert w.status() == ('ok', 'ready')
    w.set_estop(True)
    assert w.status() == ('warn', 'estop active: stopped')
    w.set_estop(False)
    assert wait_for(lambda: w.status() == ('warn', 'not homed: call home before moving'))
    w.set_enabled(False)
    assert w.status() == ('warn', 'disabled: motor off, targets refused')
