"""The bank in its own process, driven through BankClient, against emulated supplies."""

import time

import pytest
from tentacle_coils.bank_process import BankClient, RESTARTS_MAX
from tentacle_coils.errors import CommandRejected, DriverError


@pytest.fixture
def client(emulate, wait_for):
    """Return (BankClient, emulators, rejected reasons) with the outputs enabled."""
    emus = emulate('dxkdp', baud=115200)
    rejected = []
    bank = BankClient(on_rejected=rejected.append, ports=[e.port for e in emus],
                      dialect='dxkdp', baud=115200, max_current_a=10.0,
                      slew_rate_a_per_s=1000.0, watchdog_s=5.0, readback_period_s=0.05)
    assert wait_for(bank.connected)
    assert bank.enable(True) == (True, 'outputs on at zero current')
    yield bank, emus, rejected
    bank.shutdown(timeout_s=5.0)


def setpoints(emus):
    return [emu.state()['setpoint_a'] for emu in emus]


def test_commands_reach_the_supplies_and_state_comes_back(client, wait_for):
    bank, emus, _ = client
    bank.command([1.0, -2.0, 3.0])
    assert wait_for(lambda: setpoints(emus) == [1.0, -2.0, 3.0])
    assert wait_for(lambda: bank.measured_currents() == pytest.approx([1.0, -2.0, 3.0],
                                                                      abs=0.02))
    assert [s['axis'] for s in bank.snapshots()] == ['x', 'y', 'z']
    assert bank.status() == ('ok', 'enabled')


def test_refusals_come_back_with_the_reason(client, wait_for):
    bank, emus, rejected = client
    bank.command([11.0, 0.0, 0.0])
    assert wait_for(lambda: rejected)
    assert 'exceed max_current 10 A' in rejected[0]
    bank.set_estop(True)
    with pytest.raises(CommandRejected, match='estop'):
        bank.command([1.0, 1.0, 1.0])
    assert wait_for(lambda: not any(emu.state()['output_on'] for emu in emus))


def test_shutdown_confirms_zero_and_off(client, wait_for):
    bank, emus, _ = client
    bank.command([2.0, 2.0, 2.0])
    assert wait_for(lambda: setpoints(emus) == [2.0, 2.0, 2.0])
    assert bank.shutdown('test') is True
    assert bank.popen.returncode == 0
    assert setpoints(emus) == [0.0] * 3
    assert not any(emu.state()['output_on'] for emu in emus)


def test_a_vanished_node_leaves_the_coils_at_zero_and_off(client, wait_for):
    bank, emus, _ = client
    bank.command([3.0, -3.0, 3.0])
    assert wait_for(lambda: setpoints(emus) == [3.0, -3.0, 3.0])
    bank.popen.stdin.close()  # what the bank sees when the node process dies
    assert wait_for(lambda: setpoints(emus) == [0.0] * 3
                    and not any(emu.state()['output_on'] for emu in emus))
    assert bank.popen.wait(5) == 0


def test_bad_configuration_is_reported():
    with pytest.raises(DriverError, match='ports needs 3 entries'):
        BankClient(ports=['/dev/null'], dialect='dxkdp', baud=9600, max_current_a=1.0,
                   slew_rate_a_per_s=1.0, watchdog_s=1.0)


def outputs(emus):
    return [emu.state()['output_on'] for emu in emus]


@pytest.mark.parametrize('dialect', ['dxkdp', 'scpi'])
def test_a_killed_bank_is_replaced_and_every_supply_is_zero_and_off_within_a_second(
        emulate, wait_for, dialect):
    emus = emulate(dialect, baud=9600)
    rejected = []
    bank = BankClient(on_rejected=rejected.append, ports=[e.port for e in emus],
                      dialect=dialect, baud=9600,
                      max_current_a=20.0, slew_rate_a_per_s=1000.0, watchdog_s=30.0)
    try:
        assert wait_for(bank.connected) and bank.enable(True)[0]
        bank.command([15.6, -15.6, 4.0])
        assert wait_for(lambda: setpoints(emus) == [15.6, -15.6, 4.0])
        t_kill = time.monotonic()
        bank.popen.kill()  # what the OOM killer or a crash would do
        assert wait_for(lambda: setpoints(emus) == [0.0] * 3 and not any(outputs(emus)))
        t_safe = time.monotonic() - t_kill
        assert t_safe < 1.0, f'zero and off {t_safe:.2f} s after the bank died'
        level, message = bank.status()
        assert level == 'error' and 'died (exit -9)' in message
        assert wait_for(bank.connected)
        bank.command([1.0, 1.0, 1.0])  # reaches the new bank, which refuses it
        assert wait_for(lambda: rejected) and 'outputs disabled' in rejected[-1]
        time.sleep(0.3)
        assert setpoints(emus) == [0.0] * 3 and not any(outputs(emus))
        assert bank.enable(True)[0]
        assert bank.status()[0] == 'ok'
        bank.command([1.0, 1.0, 1.0])
        assert wait_for(lambda: setpoints(emus) == [1.0, 1.0, 1.0])
    finally:
        assert bank.shutdown(timeout_s=5.0)


def test_estop_is_carried_over_to_the_replacement_bank(client, wait_for):
    bank, emus, _ = client
    bank.set_estop(True)
    # Safe only once read back: an output switched on just before the estop may still be on
    # its way to the supply when the emulators first read all off.
    safe = 'estop active: outputs zero and off (read back)'
    assert wait_for(lambda: bank.status()[1] == safe)
    assert not any(outputs(emus))
    bank.popen.kill()
    assert wait_for(bank.connected)
    assert wait_for(lambda: bank.status()[1].endswith(f'(now: {safe})'))
    assert not any(outputs(emus))
    assert bank.enable(True)[0] is False  # estop still holds in the new bank
    time.sleep(0.3)
    assert not any(outputs(emus)) and bank.status()[1].endswith(f'(now: {safe})')


def test_a_bank_that_keeps_dying_is_not_replaced_for_ever(client, wait_for):
    bank, emus, _ = client
    for _ in range(RESTARTS_MAX + 1):
        assert wait_for(bank.connected)
        dead = bank.popen
        dead.kill()
        assert wait_for(lambda: bank.popen is not dead or 'not restarted' in bank.status()[1])
    assert wait_for(lambda: 'not restarted' in bank.status()[1])
    assert not bank.connected()
    with pytest.raises(CommandRejected, match='not running'):
        bank.command([1.0, 0.0, 0.0])
