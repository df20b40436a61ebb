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


@pytest.mark.parametrize('action, why', [
    ('=200', 'outside [0, 0.1] m'), ('abc', "'abc' is not an action"),
    ('+nan', 'not a finite number'), ('-1', 'outside [0, 0.1] m')])
def test_a_bad_action_is_refused_by_name_and_nothing_moves(stages, action, why):
    done = jog('--port', stages.ports['inserter'], 'home', action)
    assert done.returncode == 1 and why in done.stdout, done.stdout
    assert not [e for e in stages.log('inserter') if e['command'] == 'G1']


def test_an_unhomed_axis_and_bad_settings_are_refused_plainly(stages, tmp_path):
    done = jog('--port', stages.ports['inserter'], '+1')
    assert done.returncode == 1 and 'not homed' in done.stdout
    done = jog('--port', stages.ports['inserter'], '--max-speed', '-1', '+1')
    assert done.returncode == 1 and 'max_speed: -1.0 is outside [1e-06, 1]' in done.stderr
    done = jog('--port', str(tmp_path / 'absent'), 'home')
    assert done.returncode == 1 and 'No such file' in done.stdout


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
                           '--baud', '9600'], input='+3\n-1\np\nq\n', capture_output=True,
                          text=True, timeout=30)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert wait_for(lambda: not stages.axis('backbone')['busy'], 5.0)
    assert stages.axis('backbone')['position_m'] == pytest.approx(0.002)
    assert '2.000 mm (estimated)' in proc.stdout
    assert 'NOT confirmed by the stage (step1mm has no readback)' in proc.stdout
