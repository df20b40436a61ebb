"""
The coils node as deployed: its own process, emulated supplies on ptys, DDS topics.

Expected currents come from solving B = A I independently of the node's code (numpy), and
what reached the wire is read from the emulator's received-bytes log.
"""

import os
import signal
import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from rig_support import wait_for
from tentacle_common import contract
from tentacle_common.child_process import child_pids

pytestmark = pytest.mark.ros

REFERENCE = np.diag([0.53e-3, 1.07e-3, 0.65e-3])  # T/A, config/coils.yaml


def expected_currents(field_t, matrix=REFERENCE):
    return np.linalg.solve(matrix, field_t)


def ready(emulators, probe, timeout_s=15.0):
    """Wait until the node subscribes and has energised the outputs."""
    assert probe.wait_for_coils(timeout_s), 'coils_node did not subscribe'
    assert wait_for(lambda: all(emulators.outputs()), timeout_s), 'outputs not enabled'


def close_to(values, expected, atol):
    return np.allclose(values, expected, atol=atol)


def drive(emulators, probe, field_t, atol=0.0051):
    """Command a field; return whether every supply came to its current (one count, 5 mA)."""
    probe.send_field(field_t)
    return wait_for(lambda: close_to(emulators.setpoints(), expected_currents(field_t), atol))


@pytest.mark.parametrize('dialect, baud', [('dxkdp', 9600), ('scpi', 115200)])
def test_field_command_reaches_each_supply_and_field_agrees(coil_rig, probe, dialect, baud):
    emulators, node = coil_rig(dialect, baud)
    ready(emulators, probe)
    for field in ([5e-3, -8e-3, 3e-3], [-2e-3, 0.0, 12e-3]):
        currents = expected_currents(field)
        probe.send_field(field)
        assert wait_for(lambda: close_to(emulators.setpoints(), currents, 0.0051)), (
            f'supplies hold {emulators.setpoints()}, expected {currents}')
        t_settled = time.monotonic() + 0.2  # ten L/R time constants of the emulated coil
        # /coils/field and /coils/currents are published together but arrive on their own
        # subscriptions: wait for both, not for one and then read the other.
        assert wait_for(lambda: probe.latest('field', t_settled) is not None
                        and probe.latest('currents', t_settled) is not None)
        msg = probe.latest('field', t_settled)
        assert msg.header.frame_id == contract.COILS_FRAME
        # Stamped with the reading's (wall-clock) time: in the past and recent. That it is the
        # reading's, not the publication's, test_coil_bank checks against the emulator's log.
        age_s = time.time() - (msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
        assert 0.0 < age_s < 5.0, age_s
        measured = [msg.vector.x, msg.vector.y, msg.vector.z]
        # 0.01 A readback resolution (dxkdp) times at most 1.07 mT/A.
        assert close_to(measured, field, 2e-5), f'/coils/field {measured} vs {field}'
        cur = probe.latest('currents', t_settled)
        assert close_to([cur.vector.x, cur.vector.y, cur.vector.z], currents, 0.02)


def test_cross_coupled_matrix_and_inverted_supply(coil_rig, probe):
    matrix = np.array([[0.53e-3, 0.05e-3, 0.0], [-0.04e-3, 1.07e-3, 0.02e-3],
                       [0.0, 0.03e-3, 0.65e-3]])
    emulators, node = coil_rig('dxkdp', 115200, actuation_matrix=matrix.ravel().tolist(),
                               polarity_inverted=[False, True, False])
    ready(emulators, probe)
    field = [4e-3, 6e-3, -5e-3]
    currents = expected_currents(field, matrix)
    probe.send_field(field)
    wire = currents * [1, -1, 1]  # y is wired reversed: the wire carries the opposite sign
    assert wait_for(lambda: close_to(emulators.setpoints(), wire, 0.0051)), (
        f'{emulators.setpoints()} vs {wire}')


def test_rejected_commands_never_reach_the_wire_and_are_logged(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 115200, max_current=10.0)
    ready(emulators, probe)
    good = [2e-3, 2e-3, 2e-3]
    assert drive(emulators, probe, good)
    t_bad = time.monotonic()
    bad = [([np.nan, 0, 0], 'coils', 'not three finite'),
           ([0, np.inf, 0], 'coils', 'not three finite'),
           ([1e-3, 0, 0], 'world', "frame_id 'world' is not 'coils'"),
           ([0, 0.03, 0], 'coils', 'exceeds max_field'),
           ([0.008, 0, 0], 'coils', 'exceeds max_current')]  # 15 A on x > 10 A
    for field, frame, _ in bad:
        probe.send_field(field, frame)
    assert wait_for(lambda: all(reason in node.output() for _, _, reason in bad)), (
        node.output())
    time.sleep(0.3)
    sent = emulators.sets_since(t_bad)
    for axis, value in zip('xyz', expected_currents(good)):
        assert all(abs(current - value) < 0.0051 for current in sent[axis]), sent[axis]
    assert close_to(emulators.setpoints(), expected_currents(good), 0.0051)


def test_clamp_scales_an_over_limit_command(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 115200, clamp=True)
    ready(emulators, probe)
    probe.send_field([0.044, 0.011, 0.0])  # twice max_field on x
    scaled = expected_currents([0.022, 0.0055, 0.0])  # 41.5 A on x, within 42 A
    assert wait_for(lambda: close_to(emulators.setpoints(), scaled, 0.0051))
    assert 'clamped' in node.output()


def test_watchdog_ramps_to_zero(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 115200, watchdog_s=0.5)
    ready(emulators, probe)
    probe.send_field([5e-3, 5e-3, 5e-3])
    assert wait_for(lambda: emulators.setpoints()[0] > 9.0)
    t_last = time.monotonic()
    assert wait_for(lambda: emulators.setpoints() == [0.0, 0.0, 0.0], timeout_s=3.0)
    assert time.monotonic() - t_last >= 0.4
    assert 'watchdog' in node.output()
    assert all(emulators.outputs())  # ramped to zero, still energised


def test_estop_and_enable(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 115200)
    ready(emulators, probe)
    probe.send_field([3e-3, 3e-3, 3e-3])
    assert wait_for(lambda: emulators.setpoints()[0] > 5.0)
    probe.estop(True)
    assert wait_for(lambda: emulators.setpoints() == [0.0] * 3 and not any(emulators.outputs()))
    probe.send_field([3e-3, 3e-3, 3e-3])
    assert wait_for(lambda: 'estop active' in node.output())
    assert emulators.setpoints() == [0.0] * 3
    assert not probe.enable_coils(True)  # cannot energise under estop
    probe.estop(False)
    assert wait_for(lambda: all(emulators.outputs()))
    assert emulators.setpoints() == [0.0] * 3  # nothing moves until a new command
    assert probe.enable_coils(False)
    assert wait_for(lambda: not any(emulators.outputs()))
    probe.send_field([1e-3, 0, 0])
    assert wait_for(lambda: 'outputs disabled' in node.output())
    assert probe.enable_coils(True)
    assert drive(emulators, probe, [1e-3, 0, 0])


@pytest.mark.parametrize('kind, options', [
    ('nak', {'count': 2}), ('garble', {'count': 2}), ('late', {'count': 1, 'late_s': 0.15}),
    ('no_reply', {'count': 2})])
def test_transient_faults_are_retried_and_the_command_lands(coil_rig, probe, kind, options):
    emulators, node = coil_rig('dxkdp', 115200)
    ready(emulators, probe)
    emulators.fault('y', kind, **options)
    field = [2e-3, 4e-3, -2e-3]
    assert drive(emulators, probe, field)
    t0 = time.monotonic()
    assert wait_for(lambda: probe.status('coils: supply y', t0) is not None)
    values = probe.status('coils: supply y', t0).values
    assert int(values['retries']) >= 1
    assert node.popen.poll() is None


def test_persistent_silence_zeroes_every_axis_and_recovers(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 115200, retries=2)
    ready(emulators, probe)
    probe.send_field([3e-3, 3e-3, 3e-3])
    assert wait_for(lambda: emulators.setpoints()[1] > 2.0)
    emulators.fault('y', 'no_reply', count=3)
    probe.send_field([4e-3, 4e-3, 4e-3])
    assert wait_for(lambda: 'failed after 3 attempts' in node.output())
    assert wait_for(lambda: emulators.setpoints() == [0.0] * 3)  # no stale nonzero current
    t0 = time.monotonic()
    assert wait_for(lambda: probe.status('coils: supply y', t0) is not None)
    assert wait_for(lambda: 'fault cleared' in node.output())
    assert drive(emulators, probe, [1e-3, 1e-3, 1e-3])


def test_serial_loss_shows_in_diagnostics_reconnects_and_drives_zero(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 115200)
    ready(emulators, probe)
    assert drive(emulators, probe, [3e-3, 3e-3, 3e-3])  # the ramp is over
    emulators.fault('z', 'disconnect', duration_s=2.5)
    assert wait_for(lambda: not emulators.state()['z']['connected'])
    t_lost = time.monotonic()

    def reported(level):
        status = probe.status('coils: supply z', t_lost)
        return status is not None and status.level == level

    assert wait_for(lambda: reported(DiagnosticStatus.ERROR), timeout_s=3.0)
    assert 'disconnected' in probe.status('coils: supply z', t_lost).message
    assert emulators.setpoints()[2] > 4.0  # unplugged, the coil keeps its stale current
    assert node.popen.poll() is None
    assert wait_for(lambda: emulators.state()['z']['connected'], timeout_s=4.0)
    assert wait_for(lambda: emulators.setpoints() == [0.0] * 3, timeout_s=4.0)
    assert wait_for(lambda: reported(DiagnosticStatus.WARN) or reported(DiagnosticStatus.OK),
                    timeout_s=3.0)
    # Nothing arrives while unplugged; after reconnecting, the held current is ramped down at
    # the slew limit, every set nearer zero than the one before: never the stale setpoint.
    held = expected_currents([3e-3, 3e-3, 3e-3])[2]
    after_reconnect = emulators.sets_since(t_lost)['z']
    assert after_reconnect and after_reconnect[-1] == 0.0, after_reconnect
    assert all(0.0 <= b <= a for a, b in zip([held] + after_reconnect, after_reconnect)), (
        after_reconnect)
    # Commands are refused until the bank has read every supply back at zero and says so.
    assert wait_for(lambda: 'fault cleared' in node.output())
    assert drive(emulators, probe, [1e-3, 1e-3, 1e-3])


def test_scpi_error_queue_is_reported_and_setpoint_reasserted(coil_rig, probe):
    emulators, node = coil_rig('scpi', 115200)
    ready(emulators, probe)
    field = [2e-3, 2e-3, 2e-3]
    assert drive(emulators, probe, field, atol=1e-4)
    emulators.fault('x', 'error', count=1, code=-300, text='Device-specific error')
    t0 = time.monotonic()
    assert wait_for(lambda: (probe.status('coils: supply x', t0) is not None
                             and '-300' in probe.status('coils: supply x', t0).message))
    assert probe.status('coils: supply x', t0).level == DiagnosticStatus.WARN
    assert 'setpoint re-sent' in node.output()


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_signal_sets_outputs_to_zero_and_off_before_exit(coil_rig, probe, sig):
    emulators, node = coil_rig('dxkdp', 9600)
    ready(emulators, probe)
    probe.send_field([5e-3, -5e-3, 5e-3])
    assert wait_for(lambda: abs(emulators.setpoints()[1]) > 4.0)
    assert node.stop(sig) == 0
    assert emulators.setpoints() == [0.0] * 3
    assert not any(emulators.outputs())
    assert 'outputs zero and off' in node.output()


def test_missing_port_at_start_keeps_the_node_up_until_it_appears(coil_rig, probe, tmp_path):
    emulators, node = coil_rig('dxkdp', 115200)
    # x is absent while the node starts, long enough for a loaded machine's DDS discovery
    # to see at least one diagnostics message (1 Hz) about it.
    emulators.fault('x', 'disconnect', duration_s=6.0)
    t0 = time.monotonic()
    assert probe.wait_for_coils()
    assert wait_for(lambda: (s := probe.status('coils: supply x', t0)) is not None
                    and s.level == DiagnosticStatus.ERROR,
                    timeout_s=8.0), 'no ERROR diagnostics for the missing supply x'
    assert not any(emulators.outputs()[1:])  # not energised while a supply is missing
    assert wait_for(lambda: all(emulators.outputs()), timeout_s=12.0), (
        f'outputs {emulators.outputs()} after x came back:\n{node.output()}')
    assert node.output().count('unreachable') == 1  # logged once as an error, not per retry
    assert '[ERROR]' in node.output().split('unreachable')[0].splitlines()[-1]


def test_killed_node_still_leaves_the_coils_at_zero_and_off(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 115200)
    ready(emulators, probe)
    probe.send_field([4e-3, 4e-3, 4e-3])
    assert wait_for(lambda: emulators.setpoints()[0] > 7.0)
    node.stop(signal.SIGKILL)  # no chance to clean up: the bank process sees its input close
    assert wait_for(lambda: emulators.setpoints() == [0.0] * 3 and not any(emulators.outputs()))


@pytest.mark.parametrize('params, message', [
    ({'max_current': 'forty'}, "max_current: 'forty' is not a number"),
    ({'retries': 2.5}, 'retries: 2.5 is not an integer'),
    ({'max_field': float('nan')}, 'max_field: nan is not finite'),
    ({'max_current': 500.0}, 'max_current'),              # out of range
    ({'actuation_matrix': [1.0] * 9}, 'singular'),
    ({'polarity_mode': 'maybe'}, "polarity_mode 'maybe'"),
    ({'ports': ['/dev/a', '/dev/b']}, 'ports needs 3 entries')])
def test_bad_configuration_stops_the_node_with_the_reason(coil_rig, params, message):
    emulators, node = coil_rig('dxkdp', 115200, **params)
    assert node.popen.wait(20) == 2, node.output()
    assert 'coils_node: not started' in node.output() and message in node.output()
    assert emulators.sets_since(0.0) == {'x': [], 'y': [], 'z': []}  # nothing reached a wire


def test_integers_in_doubles_are_accepted_and_a_misspelt_parameter_is_named(coil_rig, probe):
    matrix = [0.53e-3, 0, 0, 0, 1.07e-3, 0, 0, 0, 0.65e-3]  # as people write them
    emulators, node = coil_rig('dxkdp', 115200, actuation_matrix=matrix, max_current=40,
                               max_curent=1.0)
    ready(emulators, probe)
    assert drive(emulators, probe, [2e-3, 2e-3, 2e-3])
    assert wait_for(lambda: 'max_curent is not a coils_node parameter (did you mean '
                            'max_current?): ignored' in node.output()), node.output()


def test_a_missing_params_file_is_named_and_nothing_starts(tmp_path):
    from tentacle_sim.sim_rig import NodeProcess
    missing = tmp_path / 'nowhere.yaml'
    node = NodeProcess([sys.executable, '-m', 'tentacle_coils.coils_node', '--ros-args',
                        '--params-file', str(missing)], str(tmp_path / 'node.log'))
    assert node.popen.wait(20) == 2
    assert f'params file {missing}: cannot be read' in node.output(), node.output()
    assert 'Traceback' not in node.output()


def test_signals_during_the_exit_ramp_change_nothing(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 9600, slew_rate=5.0, watchdog_s=30.0)
    ready(emulators, probe)
    probe.send_field([5e-3, 0.0, 0.0])  # 9.4 A on x, ramped at 5 A/s
    assert wait_for(lambda: emulators.setpoints()[0] > 8.0)
    node.popen.send_signal(signal.SIGINT)
    assert wait_for(lambda: emulators.setpoints()[0] < 6.0)  # the exit ramp runs
    node.popen.send_signal(signal.SIGINT)  # the second Ctrl-C, mid-ramp
    time.sleep(0.05)
    node.popen.send_signal(signal.SIGTERM)
    assert node.popen.poll() is None and emulators.setpoints()[0] > 0.0
    assert node.stop(timeout_s=15.0) == 0, node.output()
    assert 'already stopping safely' in node.output()
    assert 'Traceback' not in node.output() and 'KeyboardInterrupt' not in node.output()
    assert 'outputs zero and off' in node.output()
    assert emulators.setpoints() == [0.0] * 3 and not any(emulators.outputs())


def bank_value(probe, key, since):
    """Return (a value of the 'coils: bank' status after a time, the Status), or None."""
    status = probe.status('coils: bank', since)
    return None if status is None else (status.values.get(key), status)


def own_child(node, value):
    """Whether a diagnostics pid is this node's child (not a stray node's on the same domain)."""
    return value is not None and value[0].isdigit() and int(value[0]) in child_pids(
        node.popen.pid)


def test_a_killed_bank_process_is_replaced_and_the_coils_are_zero_and_off(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 9600)
    ready(emulators, probe)
    probe.send_field([8e-3, -8e-3, 8e-3])
    assert wait_for(lambda: emulators.setpoints()[0] > 15.0)
    t0 = time.monotonic()
    assert wait_for(lambda: own_child(node, bank_value(probe, 'bank_pid', t0)))
    pid = int(bank_value(probe, 'bank_pid', t0)[0])
    os.kill(pid, signal.SIGKILL)
    t_kill = time.monotonic()
    # How fast is bench/coils_failover.py's figure; here: that it happens.
    assert wait_for(lambda: emulators.setpoints() == [0.0] * 3 and not any(emulators.outputs()),
                    timeout_s=15.0)
    assert node.popen.poll() is None
    assert wait_for(lambda: 'coil bank process died (exit -9)' in node.output())
    assert '[ERROR]' in node.output().split('coil bank process died')[0].splitlines()[-1]
    assert wait_for(lambda: (bank_value(probe, 'bank_deaths', t_kill) or ('0',))[0] == '1')
    assert bank_value(probe, 'bank_deaths', t_kill)[1].level == DiagnosticStatus.ERROR
    probe.send_field([1e-3, 1e-3, 1e-3])
    assert wait_for(lambda: 'outputs disabled' in node.output())  # refused until enabled
    assert emulators.setpoints() == [0.0] * 3
    assert probe.enable_coils(True)
    assert drive(emulators, probe, [1e-3, 1e-3, 1e-3])


def test_the_bank_and_its_spare_killed_together_leave_the_coils_zero_and_off(coil_rig, probe):
    # Every child process of coils_node is killed while a field is held: no process was left
    # to zero the supplies, and none was started.
    emulators, node = coil_rig('dxkdp', 9600)
    ready(emulators, probe)
    probe.send_field([8e-3, -8e-3, 8e-3])
    assert wait_for(lambda: emulators.setpoints()[0] > 15.0)
    t0 = time.monotonic()
    assert wait_for(lambda: (bank_value(probe, 'spare_pid', t0) or ('none',))[0] != 'none')
    pids = child_pids(node.popen.pid)
    assert len(pids) == 2, f'expected a bank and a spare, found {pids}'
    assert emulators.setpoints()[0] > 15.0 and all(emulators.outputs())  # still held
    for pid in pids:
        os.kill(pid, signal.SIGKILL)
    t_kill = time.monotonic()
    assert wait_for(lambda: emulators.setpoints() == [0.0] * 3 and not any(emulators.outputs()),
                    timeout_s=15.0), f'supplies hold {emulators.setpoints()}: {node.output()}'
    assert node.popen.poll() is None
    assert wait_for(lambda: 'coil bank process died (exit -9)' in node.output())
    assert '[ERROR]' in node.output().split('coil bank process died')[0].splitlines()[-1]
    assert wait_for(lambda: (bank_value(probe, 'bank_deaths', t_kill) or ('0',))[0] != '0')
    assert bank_value(probe, 'bank_deaths', t_kill)[1].level == DiagnosticStatus.ERROR
    # A spare is kept again, and neither of the killed processes is it.
    assert wait_for(lambda: (bank_value(probe, 'spare_pid', t_kill) or ('none',))[0] not in (
        'none', *map(str, pids)), timeout_s=15.0)
    assert probe.enable_coils(True)
    assert drive(emulators, probe, [1e-3, 1e-3, 1e-3])


def test_a_killed_spare_is_replaced_at_once(coil_rig, probe):
    emulators, node = coil_rig('dxkdp', 115200)
    ready(emulators, probe)
    t0 = time.monotonic()
    assert wait_for(lambda: own_child(node, bank_value(probe, 'spare_pid', t0)))
    spare, bank = (int(bank_value(probe, key, t0)[0]) for key in ('spare_pid', 'bank_pid'))
    assert bank in child_pids(node.popen.pid)
    os.kill(spare, signal.SIGKILL)
    assert wait_for(lambda: 'spare process died (exit -9); a new spare started'
                    in node.output())
    t_kill = time.monotonic()
    assert wait_for(lambda: (bank_value(probe, 'spare_deaths', t_kill) or ('0',))[0] == '1')
    new_spare = bank_value(probe, 'spare_pid', t_kill)[0]
    assert new_spare not in ('none', str(spare))
    assert bank_value(probe, 'bank_pid', t_kill)[0] == str(bank)  # the bank went on
    assert drive(emulators, probe, [1e-3, 2e-3, 3e-3])
