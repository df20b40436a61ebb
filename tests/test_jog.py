"""scripts/jog as a lab user runs it, against the stage_emulator executable."""

import signal
import subprocess
import time

import pytest
from rig_support import ROOT, wait_for
from tentacle_sim.emulator_client import StageEmulatorProcess

JOG = str(ROOT / 'scripts' / 'jog')
STEP_M = 1e-5


@pytest.fixture
def stages(tmp_path):
    emus = StageEmulatorProcess(tmp_path / 'ports', axes=('inserter', 'backbone'),
                                dialects=('gcode', 'step1mm'))
    yield emus
    emus.stop()


def jog(*args, timeout_s=30.0):
    return subprocess.run([JOG, *args], capture_output=True, text=True, timeout=timeout_s)


def test_actions_run_in_turn_and_the_axis_ends_where_they_say(stages):
    port = stages.ports['inserter']
    done = jog('--port', port, '--max-speed', '0.01', 'home', '+2', '-0.5', '=3')
    assert done.returncode == 0, done.stdout + done.stderr
    truth = stages.axis('inserter')
    assert truth['position_m'] == pytest.approx(0.003, abs=STEP_M) and not truth['busy']
    assert '3.000 mm (read back)' in done.stdout
    assert done.stdout.rstrip().endswith('axis stopped at 3.000 mm (read back)')
    assert [e['E'] for e in stages.log('inserter') if e['command'] == 'G1'] == [2.0, 1.5, 3.0]


# Bad command lines, as a hostile new user tried them (issue 15 §3): every action is checked
# before the port is opened, so the stage receives nothing at all. (axis, arguments, why)
REFUSED = [
    ('inserter', ['home', '=200'], "action 2 '=200': target 0.2 m is outside [0, 0.1] m"),
    ('inserter', ['home', '+1', '=200', '+1'], "action 3 '=200': target 0.2 m is outside"),
    ('inserter', ['home', '+1', 'abc', '+1'], "action 3 'abc': 'abc' is not an action"),
    ('inserter', ['home', '+nan'], "action 2 '+nan': '+nan': not a finite number"),
    ('inserter', ['home', '-1'], "action 2 '-1': target -0.001 m is outside"),
    ('inserter', ['home', '=60', '+50'], "action 3 '+50': target 0.11 m is outside"),
    ('inserter', ['+1'], "action 1 '+1': the axis is not homed there"),
    ('inserter', ['home', '=2', 's', '+1'], "action 4 '+1': the axis is not homed there"),
    ('inserter', ['--max-speed', '-1', 'home'], 'max_speed: -1.0 is outside [1e-06, 1]'),
    ('backbone', ['--dialect', 'step1mm', '--baud', '9600', 'home', '+0.4'],
     "action 2 '+0.4': target 0.4 mm is not a whole number of mm: a step1mm axis moves in "
     'steps of 1 mm (its resolution)'),
]


@pytest.mark.parametrize('axis, args, why', REFUSED)
def test_a_bad_command_line_is_refused_whole_and_nothing_is_sent(stages, axis, args, why):
    done = jog('--port', stages.ports[axis], *args)
    assert done.returncode == 2, done.stdout + done.stderr
    assert why in done.stderr and 'nothing was done' in done.stderr, done.stderr
    assert stages.log(axis) == []                           # not even a connect
    assert stages.axis(axis)['position_m'] == 0.0 and not stages.axis(axis)['busy']


def test_the_actions_stop_at_the_first_that_fails(stages):
    stages.fault('inserter', 'stall')          # the first move never ends: it is stopped
    done = jog('--port', stages.ports['inserter'], '--max-speed', '0.01', 'home', '+1', '+1')
    assert done.returncode == 1, done.stdout + done.stderr
    assert "stopped at action 2 '+1': the 1 after it were not carried out" in done.stdout
    assert len([e for e in stages.log('inserter') if e['command'] == 'G1']) == 1


def test_an_absent_port_is_a_failure_not_a_usage_error(tmp_path):
    done = jog('--port', str(tmp_path / 'absent'), '--restart-timeout-s', '0', 'home')
    assert done.returncode == 1 and 'No such file' in done.stdout
    assert 'no stop sent (no connection)' in done.stdout


def test_the_gcode_dialect_on_a_step1mm_stage_sends_one_probe_and_moves_nothing(stages):
    done = jog('--port', stages.ports['backbone'], '--restart-timeout-s', '1', 'home', '+1')
    assert done.returncode == 1, done.stdout + done.stderr
    assert 'no gcode reply in 1 s to one probe (G90)' in done.stdout, done.stdout
    assert 'no stop sent (the device never answered)' in done.stdout
    assert [bytes.fromhex(e['hex']) for e in stages.log('backbone')] == [b'G', b'9', b'0', b'\n']
    assert stages.axis('backbone')['position_m'] == 0.0 and not stages.axis('backbone')['busy']


def test_ctrl_c_stops_the_axis_before_the_script_exits(stages):
    proc = subprocess.Popen([JOG, '--port', stages.ports['inserter'], '--max-speed', '0.01',
                             'home', '=40'], stdout=subprocess.PIPE, text=True)
    try:
        assert wait_for(lambda: stages.axis('inserter')['moving'], 10.0)
        proc.send_signal(signal.SIGINT)
        time.sleep(0.01)
        proc.send_signal(signal.SIGINT)     # a second Ctrl-C does not cut the stop short
        out, _ = proc.communicate(timeout=10)
    finally:
        proc.kill()
    truth = stages.axis('inserter')
    assert not truth['busy'] and truth['travel_m'] < 0.035
    assert 'Ctrl-C: stopping the axis' in out and 'axis stopped at' in out, out
    assert any(e['command'] == 'M112' for e in stages.log('inserter'))


def test_interactive_step1mm_counts_and_says_so(stages):
    proc = subprocess.run([JOG, '--port', stages.ports['backbone'], '--dialect', 'step1mm',
                           '--baud', '9600'], input='+3\nh\n+3\n-1\n+0.4\np\nq\n',
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 1, proc.stdout + proc.stderr  # two lines were refused
    assert wait_for(lambda: not stages.axis('backbone')['busy'], 5.0)
    assert stages.axis('backbone')['position_m'] == pytest.approx(0.002)
    assert 'not homed' in proc.stdout                       # before h: refused, as gcode's
    assert 'steps of 1 mm (its resolution)' in proc.stdout  # +0.4: refused, not 0 mm
    assert '2.000 mm (estimated)' in proc.stdout
    assert 'NOT confirmed by the stage (step1mm has no readback)' in proc.stdout
