"""
inserter_node as a real process over DDS, driving stage emulators over ptys.

The gcode emulator mostly runs in this process (its pty path is what the node opens), so
what the node publishes is checked against the emulator's true position at any instant;
the side-by-side test runs both axes in the stage_emulator executable. Every fault of the
stage emulator is injected while the node runs, and the safe state is read back from the
emulator, never assumed.
"""

import math
import os
import signal
import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
import pytest
from rig_support import wait_for
from tentacle_common import contract
from tentacle_rig.commander_node import RigCommander  # conftest claimed a private domain
from tentacle_sim.emulator_client import StageEmulatorProcess
from tentacle_sim.sim_rig import NodeProcess
from tentacle_sim.stage_emulator import GcodeStage

pytestmark = pytest.mark.ros
STEP_M = 1e-5  # 100 steps a mm
SPEED, ACCEL = 0.01, 0.5


def axis_probe(axes=('inserter',)):
    """Return the lab's facade (RigCommander) on some axes, as the tests' node; close() it."""
    return RigCommander('axis_probe', axes=axes)


def axis_status(probe, since=-math.inf, axis='inserter'):
    """Return the Status (level, message, values) of an axis after a time, or None."""
    return probe.status(f'inserter_node: {axis}', since)


def start_node(tmp_path, port, axis='inserter', **params):
    settings = {'port': port, 'axis': axis, 'max_length': 0.05, 'max_speed': SPEED,
                'acceleration': ACCEL, 'reply_timeout_s': 0.2, **params}
    argv = [sys.executable, '-m', 'tentacle_inserter.inserter_node', '--ros-args']
    if axis != 'inserter':
        argv += ['-r', f'__node:={contract.axis_node_name(axis)}']
    for name, value in settings.items():
        argv += ['-p', f'{name}:={value}']
    return NodeProcess(argv, str(tmp_path / f'{axis}.log'))


@pytest.fixture
def axis(tmp_path):
    """Return (probe, gcode emulator, node), homed; the node is stopped with SIGINT after."""
    link = str(tmp_path / 'stage')
    emu = GcodeStage('e', link_path=link, accel_m_s2=ACCEL).start()
    node = start_node(tmp_path, link)
    probe = axis_probe()
    try:
        assert probe.home(timeout_s=20.0), node.output()
        yield probe, emu, node
    finally:
        probe.close()
        code = node.stop()
        emu.stop()
        assert code in (0, -signal.SIGKILL), node.output()


def sent(emu, command, since=0.0):
    return [e for e in emu.log if e.get('command') == command and e['t'] >= since]


def truth(emu):
    return emu.state()['position_m']


def test_a_target_moves_the_axis_and_state_follows_the_truth(axis):
    probe, emu, node = axis
    probe.send_target('inserter', 0.008)
    assert wait_for(lambda: truth(emu) == pytest.approx(0.008, abs=STEP_M), 10)
    since = time.monotonic() + 0.2
    assert wait_for(lambda: probe.position_m('inserter', since) is not None, 2.0)
    assert abs(probe.position_m('inserter', since) - truth(emu)) <= STEP_M
    assert wait_for(lambda: (axis_status(probe, since) or (None,))[0] == DiagnosticStatus.OK, 3.0)
    assert axis_status(probe, since)[2]['position'] == 'measured'


@pytest.mark.parametrize('bad', [math.nan, math.inf, -0.001, 0.06])
def test_a_bad_target_is_refused_and_never_reaches_the_wire(axis, bad):
    probe, emu, node = axis
    probe.send_target('inserter', bad)
    assert wait_for(lambda: 'target refused' in node.output(), 5.0)
    time.sleep(0.3)
    assert not sent(emu, 'G1')


def test_stop_and_estop_halt_and_hold(axis):
    probe, emu, node = axis
    probe.send_target('inserter', 0.04)
    assert wait_for(lambda: emu.state()['moving'], 5.0)
    assert probe.stop_axis()
    assert wait_for(lambda: not emu.state()['busy'], 1.0)
    assert probe.home()
    probe.estop(True)
    time.sleep(0.3)
    moves = len(sent(emu, 'G1'))
    for target in (0.01, 0.02, 0.03):
        probe.send_target('inserter', target)
    time.sleep(0.5)
    assert len(sent(emu, 'G1')) == moves and not emu.state()['busy']
    assert not probe.home()        # no home under estop either
    probe.estop(False)


def test_a_killed_node_leaves_the_axis_stopped(axis):
    probe, emu, node = axis
    probe.send_target('inserter', 0.04)
    assert wait_for(lambda: emu.state()['moving'], 5.0)
    t_kill = time.monotonic()
    node.stop(signal.SIGKILL)    # no chance to clean up: the axis process sees its input close
    assert wait_for(lambda: not emu.state()['busy'], 2.0)
    assert time.monotonic() - t_kill < 1.5
    assert sent(emu, 'M112', t_kill) and emu.state()['travel_m'] < 0.03


def test_a_stalled_move_is_reported_and_the_axis_stopped(axis):
    probe, emu, node = axis
    probe.send_target('inserter', 0.01)
    assert wait_for(lambda: emu.state()['moving'], 5.0)
    t0 = time.monotonic()
    emu.inject('stall')          # the position stops advancing; M400 never answers
    allowed = 1.5 * (0.01 / SPEED + SPEED / ACCEL) + 0.5
    assert wait_for(lambda: sent(emu, 'M112', t0), allowed + 2.0)
    assert wait_for(lambda: 'did not finish' in node.output(), 2.0), node.output()
    assert wait_for(lambda: (axis_status(probe, t0 + allowed) or (None, ''))[1].startswith(
        'not homed'), 3.0)
    assert axis_status(probe, t0 + allowed)[0] == DiagnosticStatus.WARN
    since = time.monotonic() + 0.1
    assert wait_for(lambda: probe.position_m('inserter', since) is not None, 2.0)
    # read back where it stalled
    assert abs(probe.position_m('inserter', since) - truth(emu)) <= STEP_M


@pytest.mark.parametrize('factor, finishes', [(0.9, True), (0.3, False)])
def test_a_slow_move_finishes_within_its_margin_or_is_stopped(axis, factor, finishes):
    probe, emu, node = axis
    emu.inject('slow', factor=factor)
    t0 = time.monotonic()
    probe.send_target('inserter', 0.02)
    if finishes:
        assert wait_for(lambda: truth(emu) == pytest.approx(0.02, abs=STEP_M)
                        and not emu.state()['busy'], 10.0)
        time.sleep(0.3)
        assert not sent(emu, 'M112', t0)
    else:
        assert wait_for(lambda: sent(emu, 'M112', t0), 10.0)
        assert not emu.state()['busy'] and emu.state()['travel_m'] < 0.02
        assert wait_for(lambda: 'did not finish' in node.output(), 2.0)


def test_a_lost_ok_is_retried_and_the_axis_moves_once(axis):
    probe, emu, node = axis
    t0 = time.monotonic()
    emu.inject('drop_reply', count=1, match='G1')
    probe.send_target('inserter', 0.005)
    assert wait_for(lambda: truth(emu) == pytest.approx(0.005, abs=STEP_M)
                    and not emu.state()['busy'], 10.0)
    assert len(sent(emu, 'G1', t0)) == 2                  # the same absolute line twice
    time.sleep(0.3)
    assert not sent(emu, 'M112', t0) and truth(emu) == pytest.approx(0.005, abs=STEP_M)


def test_a_lost_line_reconnects_reads_back_and_replays_nothing(axis):
    probe, emu, node = axis
    probe.send_target('inserter', 0.01)
    assert wait_for(lambda: emu.state()['moving'], 5.0)
    outage_s = 5.0               # long enough for the status, the target and its refusal
    emu.inject('disconnect', duration_s=outage_s)
    t_lost = time.monotonic()
    assert wait_for(lambda: (axis_status(probe, t_lost) or (None,))[0] == DiagnosticStatus.ERROR,
                    4.0)
    # During the outage: refused, not kept for the reconnect.
    probe.send_target('inserter', 0.03)
    assert wait_for(lambda: 'target refused: not connected' in node.output(), 4.0), \
        node.output()
    assert not emu.state()['connected']                   # it was refused in the outage
    assert wait_for(lambda: sent(emu, 'M114', t_lost + outage_s), 6.0)   # read back, again
    t_back = time.monotonic()
    assert wait_for(lambda: (axis_status(probe, t_back) or (None, ''))[1].startswith(
        'not homed'), 4.0)
    travel = emu.state()['travel_m']
    assert not sent(emu, 'G1', t_lost)                    # neither target is replayed
    probe.send_target('inserter', 0.02)   # nor a new one taken, unhomed
    assert wait_for(lambda: 'not homed' in node.output().split('line lost')[-1], 3.0)
    assert not sent(emu, 'G1', t_lost) and not emu.state()['busy']
    assert emu.state()['travel_m'] == travel              # nothing moved it since the return


def test_a_firmware_reset_mid_move_is_caught_and_read_back(axis):
    probe, emu, node = axis
    probe.send_target('inserter', 0.02)
    assert wait_for(lambda: truth(emu) > 0.003, 5.0)
    t0 = time.monotonic()
    emu.inject('reset')          # the board restarts: it forgets the move and counts from 0
    stood = emu.state()['travel_m']
    assert wait_for(lambda: sent(emu, 'M114', t0), 1.5)   # at its 'start', not at a timeout
    # The read-back reaches the stage before the failure's log line reaches the node's log.
    assert wait_for(lambda: 'restarted during the move' in node.output(), 3.0)
    t_back = time.monotonic()
    assert wait_for(lambda: (axis_status(probe, t_back) or (None, ''))[1].startswith(
        'not homed'), 5.0), (axis_status(probe), node.output())
    since = time.monotonic() + 0.1
    assert wait_for(lambda: probe.position_m('inserter', since) is not None, 2.0)
    assert probe.position_m('inserter', since) == pytest.approx(truth(emu), abs=STEP_M) == 0.0
    assert emu.state()['travel_m'] == pytest.approx(stood)    # and nothing moved it since


def test_a_firmware_that_restarts_after_m112_is_waited_for_and_read_back(tmp_path):
    link = str(tmp_path / 'stage')
    emu = GcodeStage('e', link_path=link, accel_m_s2=ACCEL, reset_after_halt_s=1.0).start()
    node = start_node(tmp_path, link, steps_per_mm=80.0)  # the firmware boots with 100
    probe = axis_probe()
    try:
        assert probe.home(timeout_s=20.0), node.output()
        probe.send_target('inserter', 0.02)
        assert wait_for(lambda: truth(emu) > 0.002, 5.0)
        t_stop = time.monotonic()
        assert probe.stop_axis()
        assert wait_for(lambda: not emu.state()['busy'], 0.5)      # halted at once
        stood = emu.state()['travel_m']
        assert wait_for(lambda: emu.state()['halted'] is False, 3.0)  # it restarted by itself
        # The driver waited for it, set it up again (M92 after the restart) and read it back.
        assert wait_for(lambda: [e['command'] for e in emu.log if e['t'] > t_stop + 1.0][-2:]
                        == ['M92', 'M114'], 3.0), node.output()
        since = time.monotonic() + 0.1
        assert wait_for(lambda: probe.position_m('inserter', since) is not None, 2.0)
        # A restart counts from 0 here.
        assert probe.position_m('inserter', since) == 0.0 == truth(emu)
        assert emu.state()['travel_m'] == stood and emu.state()['steps_per_mm'] == 80.0
        assert probe.home()
        probe.send_target('inserter', 0.001)
        assert wait_for(lambda: truth(emu) == pytest.approx(0.001, abs=STEP_M), 5.0)
        assert emu.state()['travel_m'] == pytest.approx(stood + 0.001, abs=STEP_M)
    finally:
        probe.close()
        code = node.stop()
        emu.stop()
    assert code == 0, node.output()


def test_a_killed_axis_process_is_replaced_and_the_axis_halted(axis):
    probe, emu, node = axis
    probe.send_target('inserter', 0.04)
    assert wait_for(lambda: emu.state()['moving'], 5.0)
    assert wait_for(lambda: axis_status(probe) is not None, 3.0)
    pid = int(axis_status(probe)[2]['pid'])
    t_kill = time.monotonic()
    os.kill(pid, signal.SIGKILL)  # a crash of the axis process: the node's spare takes over
    assert wait_for(lambda: not emu.state()['busy'], 2.0)
    assert time.monotonic() - t_kill < 1.5
    assert wait_for(lambda: 'died (exit -9)' in (axis_status(probe, t_kill) or (0, ''))[1], 4.0)
    assert axis_status(probe, t_kill)[0] == DiagnosticStatus.ERROR
    assert probe.home()
    probe.send_target('inserter', 0.002)
    assert wait_for(lambda: truth(emu) == pytest.approx(0.002, abs=STEP_M), 5.0)


def test_inserter_and_backbone_side_by_side_gcode_and_step1mm(tmp_path):
    emus = StageEmulatorProcess(tmp_path / 'ports', axes=('inserter', 'backbone'),
                                dialects=('gcode', 'step1mm'))
    nodes = [start_node(tmp_path, emus.ports['inserter']),
             start_node(tmp_path, emus.ports['backbone'], axis='backbone', dialect='step1mm',
                        baud=9600)]
    probe = axis_probe(('inserter', 'backbone'))
    try:
        assert probe.home('inserter', timeout_s=20.0), nodes[0].output()
        assert probe.home('backbone', timeout_s=20.0), nodes[1].output()
        probe.send_target('inserter', 0.006)
        probe.send_target('backbone', 0.003)
        assert wait_for(lambda: emus.axis('inserter')['position_m'] == pytest.approx(
            0.006, abs=STEP_M) and emus.axis('backbone')['position_m'] == pytest.approx(
            0.003, abs=1e-9) and not emus.axis('backbone')['busy'], 10.0)
        since = time.monotonic() + 0.2
        assert wait_for(lambda: probe.position_m('backbone', since) is not None
                        and probe.position_m('inserter', since) is not None, 3.0)
        assert probe.position_m('backbone', since) == pytest.approx(0.003)   # counted
        assert abs(probe.position_m('inserter', since) - 0.006) <= STEP_M   # read back
        assert wait_for(lambda: axis_status(probe, since, 'backbone') is not None, 3.0)
        assert axis_status(probe, since, 'backbone')[2]['position'].startswith('estimated')
        commands = [e['command'] for e in emus.log('backbone')]
        assert commands == ['stop', 'extend', 'extend', 'extend']
        assert {'inserter_node', 'backbone_node'} <= set(probe.get_node_names())
        assert probe.stop_axis('backbone')
        assert wait_for(lambda: [e['command'] for e in emus.log('backbone')][-1] == 'stop')
    finally:
        probe.close()
        codes = [node.stop() for node in nodes]
        emus.stop()
    assert codes == [0, 0], [node.output() for node in nodes]


@pytest.mark.parametrize('argv, message', [
    (['-p', 'axis:=in-serter'], "axis: 'in-serter' is not a ROS name token"),
    (['-p', 'axis:=backbone'], 'add -r __node:=backbone_node'),   # not a second inserter_node
])
def test_an_axis_that_cannot_run_is_refused_at_start(tmp_path, argv, message):
    node = NodeProcess([sys.executable, '-m', 'tentacle_inserter.inserter_node', '--ros-args',
                        '-p', f'port:={tmp_path / "absent"}', *argv], str(tmp_path / 'n.log'))
    try:
        code = node.popen.wait(30)
    finally:
        node.stop()
    assert code == 2, node.output()
    assert message in node.output()
    assert 'Traceback' not in node.output()
