"""
The axis worker: latest target, stop, estop, a lost line.

Most tests run it against the gcode emulator on a pty; the outage tests turn its thread by
hand (``_step``) on a scripted line, so the order of loss, target and reconnect is forced.
"""

import time

import pytest
from tentacle_common.scripted_line import Exchange, ScriptedLine
from tentacle_common.serial_line import SerialLine
from tentacle_inserter import stage, step1mm
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


def step1mm_worker():
    """Return (worker, line): a step1mm axis on a scripted line, connected and homed."""
    line = ScriptedLine([Exchange(b'3')], baud=step1mm.BAUD)     # the stop at connect
    w = AxisWorker(stage.Step1mmStage(line, max_length_m=0.05), reconnect_s=0.0)
    w._step(0.0)
    assert w.connected
    w.home(timeout_s=0.0)        # asked for; the next turn does it
    w._step(0.0)
    assert w.snapshot()['homed']
    return w, line


def test_a_target_during_an_outage_is_refused_and_nothing_moves_after_it():
    w, line = step1mm_worker()
    line.close()                 # the adapter is unplugged: the next write finds out
    w.set_target(0.002)
    w._step(0.0)
    assert not w.connected and w.error.startswith('line lost')
    with pytest.raises(stage.TargetRefused, match='not connected: line lost'):
        w.set_target(0.005)      # during the outage: refused, not kept
    line.script.append(Exchange(b'3'))                          # back: a stop, no more
    w._step(0.0)
    assert w.connected and not w.snapshot()['homed']
    w._step(0.0)                 # nothing is left to do: the script fails on any byte
    with pytest.raises(stage.TargetRefused, match='not homed'):
        w.set_target(0.005)      # a step1mm axis is unhomed by a connect, as gcode is
    line.finish()
    assert w.idle() and w.moves == 0 and w.refusals == 2


def test_a_connect_drops_a_target_pending_from_before_it():
    line = ScriptedLine([Exchange(b'3')], baud=step1mm.BAUD)
    w = AxisWorker(stage.Step1mmStage(line, max_length_m=0.05), reconnect_s=0.0)
    w._target = 0.003            # left by any path (before the fix: set_target in an outage)
    w._step(0.0)
    assert w.connected and w.idle()
    line.finish()


def test_a_device_that_never_answers_is_not_tried_again_and_not_stopped():
    line = ScriptedLine([Exchange(b'G90\n')], baud=115200)        # a probe, and silence
    axis = stage.GcodeStage(line, max_length_m=0.05, max_speed_m_s=SPEED, accel_m_s2=ACCEL,
                            steps_per_mm=100.0, reply_timeout_s=0.2, restart_timeout_s=1.0)
    w = AxisWorker(axis, reconnect_s=0.0)
    w._step(0.0)
    assert not w.connected and 'never answers' in w.gave_up
    w.stop()
    for _ in range(3):
        w._step(0.0)             # no reconnect, no stop: the script fails on any byte
    assert w.home(timeout_s=0.0)[0] is False
    w._step(0.0)
    assert w._home_result == (False, w.error)
    w._close()
    line.finish()
    assert not w.stopped and w.status() == ('error', w.error)
