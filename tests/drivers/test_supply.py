"""Supply drivers against emulated devices over real pseudo-terminals."""

import time

import pytest

from tentacle_coils.errors import ConfigError, LinkLost, SupplyFault
from tentacle_coils.supply import make_supply
from tentacle_common.serial_line import SerialLine


def connected(emu, dialect, baud, **kwargs):
    line = SerialLine(emu.port, baud)
    line.open()
    supply = make_supply(dialect, line, **kwargs)
    supply.connect()
    return supply


def sets(emu):
    return [e['current_a'] for e in emu.log if 'current_a' in e]


@pytest.mark.parametrize('mode', ['signed', 'command'])
@pytest.mark.parametrize('inverted', [False, True])
def test_dxkdp_signed_currents_reach_the_coil_in_both_generations(emulate, mode, inverted):
    emu, = emulate('dxkdp', names='x', baud=115200, polarity_mode=mode)
    supply = connected(emu, 'dxkdp', 115200, polarity_mode=mode, polarity_inverted=inverted)
    supply.set_output(True)
    for current_a in (2.0, -1.5, 0.25):
        supply.set_current(current_a)
        assert emu.state()['setpoint_a'] == pytest.approx(-current_a if inverted else current_a)
    time.sleep(0.1)
    assert supply.read_current() == pytest.approx(0.25, abs=0.011)
    supply.line.close()


def test_dxkdp_connect_programs_the_voltage_limit_and_reports_what_is_held(emulate):
    emu, = emulate('dxkdp', names='x', baud=115200)
    emu.load.drive(setpoint_a=3.0, output_on=True)  # left from an earlier session
    supply = connected(emu, 'dxkdp', 115200, voltage_limit_v=24.0)
    assert emu.state()['voltage_limit_v'] == 24.0
    assert supply.read_held() == (pytest.approx(3.0), True)  # the channel ramps it down
    supply.line.close()


def test_first_generation_polarity_changes_only_at_zero(emulate):
    emu, = emulate('dxkdp', names='x', baud=115200, polarity_mode='command')
    earlier = connected(emu, 'dxkdp', 115200, polarity_mode='command')
    earlier.set_output(True)
    earlier.set_current(-2.0)  # an earlier session left the unit at -2 A
    earlier.line.close()
    supply = connected(emu, 'dxkdp', 115200, polarity_mode='command')  # polarity unknown
    for magnitude_a in (1.5, 0.5, 0.0):  # the channel ramps |2 A| down as it flows
        supply.set_current(magnitude_a)
        assert emu.state()['setpoint_a'] == pytest.approx(-magnitude_a)
    supply.set_current(1.0)  # from zero, the polarity is set first
    assert emu.state()['setpoint_a'] == pytest.approx(1.0)
    supply.set_current(-1.0)  # a direct change of sign goes through zero, never jumps
    assert emu.state()['setpoint_a'] == pytest.approx(-1.0)
    values = [e.get('current_a') for e in emu.log if 'current_a' in e]
    assert values[-2:] == [0.0, -1.0] or values[-3:-1] == [0.0, 0.0]
    supply.line.close()


@pytest.mark.parametrize('kind', ['nak', 'garble', 'no_reply', 'late'])
def test_transient_faults_are_retried(emulate, kind):
    emu, = emulate('dxkdp', names='x', baud=115200)
    supply = connected(emu, 'dxkdp', 115200, retries=3, reply_timeout_s=0.05)
    emu.inject(kind, count=2, late_s=0.2)
    supply.set_current(1.0)
    assert emu.state()['setpoint_a'] == 1.0
    # A late ACK may answer the retry after it (same idempotent setpoint), so 'late' may
    # need one attempt more than the faults injected; never more than the bound.
    assert 2 <= supply.counters['retries'] <= 3 if kind == 'late' else \
        supply.counters['retries'] == 2
    supply.line.close()


def test_persistent_fault_raises_after_bounded_attempts(emulate):
    emu, = emulate('dxkdp', names='x', baud=115200)
    supply = connected(emu, 'dxkdp', 115200, retries=2, reply_timeout_s=0.02)
    emu.inject('nak', count=10)
    t0 = time.monotonic()
    with pytest.raises(SupplyFault, match='CURRENT failed after 3 attempts.*NAK'):
        supply.set_current(1.0)
    assert time.monotonic() - t0 < 0.5
    assert sets(emu).count(1.0) == 3
    supply.line.close()


def test_lost_link_raises_link_lost(emulate):
    emu, = emulate('dxkdp', names='x', baud=115200)
    supply = connected(emu, 'dxkdp', 115200)
    emu.inject('disconnect', duration_s=1.0)
    time.sleep(0.1)
    with pytest.raises(LinkLost):
        supply.set_current(1.0)
    assert not supply.line.is_open


def test_scpi_set_read_and_check(emulate):
    emu, = emulate('scpi', names='x', baud=115200)
    supply = connected(emu, 'scpi', 115200, polarity_inverted=True)
    assert supply.identity.startswith('Emulated BPS-x')
    supply.set_output(True)
    supply.set_current(1.2345)
    assert supply.read_setpoint() == pytest.approx(1.2345)
    assert emu.state()['setpoint_a'] == pytest.approx(-1.2345)
    time.sleep(0.1)
    assert supply.read_current() == pytest.approx(1.2345, abs=1e-3)
    assert supply.errors() == [] and supply.read_held() == (pytest.approx(1.2345), True)
    emu.inject('error', count=1, code=-222, text='Data out of range')
    emu.inject('no_reply', count=1)  # the next set is lost silently, as SCPI allows
    supply.set_current(2.0)
    assert supply.errors() == ['-222,"Data out of range"']
    assert supply.read_held() == (pytest.approx(1.2345), True)  # not 2 A: the set was lost
    supply.line.close()


def test_dxkdp_read_back_reports_the_setpoint_and_output(emulate):
    emu, = emulate('dxkdp', names='x', baud=115200)
    supply = connected(emu, 'dxkdp', 115200, polarity_inverted=True)
    supply.set_output(True)
    supply.set_current(-2.5)
    assert supply.read_held() == (pytest.approx(-2.5), True)
    assert emu.state()['setpoint_a'] == pytest.approx(2.5)
    supply.line.close()


def test_scpi_nak_queues_an_error_as_the_device_would(emulate):
    emu, = emulate('scpi', names='x', baud=115200)
    supply = connected(emu, 'scpi', 115200)
    emu.inject('nak', count=1)
    supply.set_current(1.0)  # refused: no reply on the line, -222 in the error queue
    assert supply.errors() == ['-222,"Data out of range"']
    assert supply.read_setpoint() == 0.0
    supply.line.close()


def test_unknown_dialect_and_polarity_mode_are_config_errors():
    with pytest.raises(ConfigError, match="dialect 'modbus'"):
        make_supply('modbus', SerialLine('/dev/null', 9600))
    with pytest.raises(ConfigError, match="polarity_mode 'maybe'"):
        make_supply('dxkdp', SerialLine('/dev/null', 9600), polarity_mode='maybe')


def test_open_of_missing_port_is_link_lost(tmp_path):
    with pytest.raises(LinkLost, match='cannot open'):
        SerialLine(str(tmp_path / 'nothing'), 9600).open()
