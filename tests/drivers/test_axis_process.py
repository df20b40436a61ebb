"""The axis in its own process, driven through AxisClient, against the stage emulators."""

import time

import pytest
from tentacle_common.errors import ConfigError
from tentacle_inserter.axis_process import AxisClient
from tentacle_inserter.params import INSERTER_PARAMS
from tentacle_inserter.stage import TargetRefused
from tentacle_sim.stage_emulator import GcodeStage, Step1mmStage

DEFAULTS = {p.name: p.default for p in INSERTER_PARAMS}
STEP_M = 1e-5


def params(link, **overrides):
    return {**DEFAULTS, 'port': link, 'max_length': 0.05, 'max_speed': 0.01,
            'acceleration': 0.5, 'reply_timeout_s': 0.2, **overrides}


@pytest.fixture
def client(tmp_path, wait_for):
    """Return (AxisClient, emulator, refusals), homed."""
    link = str(tmp_path / 'stage')
    emu = GcodeStage('e', link_path=link, accel_m_s2=0.5).start()
    refused = []
    axis = AxisClient(params(link), on_refused=refused.append)
    try:
        assert wait_for(lambda: axis.snapshot()['connected'])
        assert axis.home() == (True, 'zero is here')
        yield axis, emu, refused
    finally:
        axis.shutdown()
        emu.stop()


def commands(emu, since=0):
    return [e['command'] for e in emu.log[since:]]


def test_a_target_moves_the_axis_and_the_snapshot_follows(client, wait_for):
    axis, emu, _ = client
    axis.set_target(0.005)
    # While the firmware is busy with the move, the snapshot is its profile, and says so.
    assert wait_for(lambda: axis.snapshot()['moving'] and axis.snapshot()['estimated'])
    assert wait_for(lambda: axis.snapshot()['moves'] == 1 and not axis.snapshot()['moving'])
    assert abs(axis.snapshot()['position_m'] - emu.state()['position_m']) <= STEP_M
    assert axis.status() == ('ok', 'ready')


def test_bad_targets_are_refused_before_the_process(client):
    axis, emu, _ = client
    for bad in (float('nan'), float('inf'), -1e-3, 0.051, 'x'):
        with pytest.raises(TargetRefused):
            axis.set_target(bad)
    axis.set_estop(True)
    with pytest.raises(TargetRefused, match='estop'):
        axis.set_target(0.01)
    assert 'G1' not in commands(emu) and axis.snapshot()['refusals'] == 6


def test_a_vanished_node_leaves_the_axis_stopped(client, wait_for):
    axis, emu, _ = client
    axis.set_target(0.04)
    assert wait_for(lambda: emu.state()['moving'])
    axis.popen.stdin.close()        # what the axis process sees when the node dies
    assert wait_for(lambda: not emu.state()['busy'], 1.0)
    assert axis.popen.wait(5) == 0
    assert 'M112' in commands(emu, commands(emu).index('G1'))
    assert emu.state()['travel_m'] < 0.03


def test_a_killed_axis_process_is_replaced_and_the_axis_halted(client, wait_for):
    axis, emu, refused = client
    axis.set_target(0.04)
    assert wait_for(lambda: emu.state()['moving'])
    t_kill = time.monotonic()
    axis.popen.kill()               # a crash, or the OOM killer: no chance to stop
    assert wait_for(lambda: not emu.state()['busy'], 2.0)
    t_halted = time.monotonic() - t_kill
    assert t_halted < 1.0, f'halted {t_halted:.2f} s after the axis process died'
    assert wait_for(lambda: axis.snapshot()['connected'])
    level, message = axis.status()
    assert level == 'error' and 'died (exit -9)' in message
    assert not axis.snapshot()['homed']
    axis.set_target(0.01)           # reaches the new process, which refuses: not homed
    assert wait_for(lambda: refused) and 'not homed' in refused[-1]
    assert axis.home() == (True, 'zero is here')
    assert wait_for(lambda: axis.status() == ('ok', 'ready'))   # the next state says so
    axis.set_target(0.002)
    assert wait_for(lambda: abs(emu.state()['position_m'] - 0.002) <= STEP_M
                    and not emu.state()['busy'])


def test_estop_is_carried_over_to_the_replacement(client, wait_for):
    axis, emu, _ = client
    axis.set_estop(True)
    axis.popen.kill()
    assert wait_for(lambda: axis.snapshot()['connected'])
    assert wait_for(lambda: 'estop active' in axis.status()[1])
    assert axis.home() == (False, 'estop active')
    axis.set_estop(False)
    assert wait_for(lambda: 'estop' not in axis.status()[1])


def test_a_bad_configuration_is_reported(tmp_path):
    with pytest.raises(ConfigError, match="dialect 'canopen' is not gcode or step1mm"):
        AxisClient(params(str(tmp_path / 'none'), dialect='canopen'))


def test_step1mm_axis_follows_its_profile_and_stops_when_the_node_goes(tmp_path, wait_for):
    link = str(tmp_path / 'stage')
    emu = Step1mmStage('e', link_path=link, speed_m_s=0.01).start()
    axis = AxisClient(params(link, dialect='step1mm', baud=9600))
    try:
        assert wait_for(lambda: axis.snapshot()['connected'])
        assert axis.home() == (True, 'zero is here')       # a step1mm axis too starts unhomed
        axis.set_target(0.01)
        assert wait_for(lambda: emu.state()['moving'])
        # The counted position follows the moves' expected profile, and says it is estimated.
        assert wait_for(lambda: 0.002 < axis.snapshot()['position_m'] < 0.008)
        assert axis.snapshot()['estimated'] and axis.snapshot()['moving']
        axis.popen.stdin.close()
        assert wait_for(lambda: not emu.state()['busy'], 1.0)
        assert emu.state()['position_m'] < 0.01
        assert [e['command'] for e in emu.log][-1] == 'stop'
    finally:
        axis.shutdown()
        emu.stop()
