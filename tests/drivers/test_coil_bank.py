"""The coil bank against three emulated supplies over real pseudo-terminals."""

import time

import numpy as np
import pytest

from tentacle_coils.coil_bank import build_bank
from tentacle_coils.errors import CommandRejected

BUNCHING_S = 0.02  # how far late stamps may shorten a window between two sets (s)


@pytest.fixture
def rig(emulate, wait_for):
    """Return a factory of (enabled bank, its emulators) for a dialect and bank options."""
    banks = []

    def make(dialect='dxkdp', baud=115200, emulator=None, **kwargs):
        emus = emulate(dialect, baud=baud, **(emulator or {}))
        options = {'max_current_a': 10.0, 'slew_rate_a_per_s': 1000.0, 'watchdog_s': 5.0,
                   'readback_period_s': 0.05, 'reply_timeout_s': 0.03, **kwargs}
        bank = build_bank([e.port for e in emus], dialect=dialect, baud=baud, **options)
        bank.start()
        banks.append(bank)
        assert wait_for(bank.connected), 'supplies did not connect'
        assert bank.enable(True)[0]
        return bank, emus

    yield make
    for bank in banks:
        bank.shutdown(timeout_s=1.0)


def setpoints(emus):
    return [emu.state()['setpoint_a'] for emu in emus]


def set_entries(emu, since=0.0):
    return [(e['t'], e['current_a']) for e in emu.log if 'current_a' in e and e['t'] >= since]


@pytest.mark.parametrize('dialect', ['dxkdp', 'scpi'])
def test_each_command_reaches_each_supply(rig, dialect, wait_for):
    bank, emus = rig(dialect)
    bank.command([1.5, -2.25, 3.0])
    assert wait_for(lambda: setpoints(emus) == [1.5, -2.25, 3.0])
    assert all(emu.state()['output_on'] for emu in emus)
    assert wait_for(lambda: np.allclose(bank.measured_currents(), [1.5, -2.25, 3.0],
                                        atol=0.02))


def test_slew_rate_is_never_exceeded(rig, wait_for):
    slew = 100.0
    bank, emus = rig(slew_rate_a_per_s=slew)
    t_command = time.monotonic()
    bank.command([5.0, -5.0, 0.0])
    assert wait_for(lambda: setpoints(emus)[:2] == [5.0, -5.0])
    for emu in emus[:2]:
        entries = [(t_command, 0.0)] + set_entries(emu, since=t_command)
        times, values = np.array(entries).T
        # The emulators stamp a set when their thread reads it, and they share this process's
        # GIL with the bank: under load a read comes late, by multiples of the 5 ms switch
        # interval, and bunches the sets behind it. A late stamp only makes a set look later,
        # so no set may arrive before the slew limit allows it from the command: exact, to
        # half the supply's 10 mA count.
        assert np.all(np.abs(values) <= slew * (times - t_command) + 0.005 + 1e-9)
        # Between two sets, bunching shortens the window by up to BUNCHING_S: no jump, though
        # (the exact set-by-set check is test_protocol.py's, on a virtual clock).
        later = np.triu(np.ones((len(times),) * 2, dtype=bool), k=1)
        change = np.abs(values[None, :] - values[:, None])[later]
        window = (times[None, :] - times[:, None])[later]
        assert np.all(change <= slew * (window + BUNCHING_S))
        assert len(entries) > 5  # ramped in steps, not jumped


def test_rejected_commands_never_reach_the_wire(rig, wait_for):
    bank, emus = rig()
    bank.command([1.0, 1.0, 1.0])
    assert wait_for(lambda: setpoints(emus) == [1.0, 1.0, 1.0])
    t_bad = time.monotonic()
    for bad, reason in (([11.0, 0, 0], 'exceed max_current'), ([np.nan, 0, 0], 'finite'),
                        ([0, np.inf, 0], 'finite'), ([1.0, 2.0], 'three')):
        with pytest.raises(CommandRejected, match=reason):
            bank.command(bad)
    time.sleep(0.2)
    assert all(value == 1.0 for emu in emus for _, value in set_entries(emu, since=t_bad))


def test_commands_need_enable(rig, wait_for):
    bank, emus = rig()
    assert bank.enable(False)[0]
    assert wait_for(lambda: not any(emu.state()['output_on'] for emu in emus))
    with pytest.raises(CommandRejected, match='disabled'):
        bank.command([1.0, 0, 0])


def test_watchdog_ramps_to_zero_and_leaves_outputs_on(rig, wait_for):
    bank, emus = rig(watchdog_s=0.3)
    bank.command([2.0, 2.0, 2.0])
    assert wait_for(lambda: setpoints(emus) == [2.0, 2.0, 2.0])
    assert wait_for(lambda: setpoints(emus) == [0.0, 0.0, 0.0], timeout_s=1.0)
    assert bank.status()[0] == 'warn' and 'watchdog' in bank.status()[1]
    assert all(emu.state()['output_on'] for emu in emus)
    bank.command([1.0, 0.0, 0.0])  # a new command resumes
    assert wait_for(lambda: setpoints(emus)[0] == 1.0)


def test_supply_that_stops_answering_zeroes_all_axes_then_recovers(rig, wait_for):
    bank, emus = rig(retries=2)
    bank.command([3.0, 3.0, 3.0])
    assert wait_for(lambda: setpoints(emus) == [3.0, 3.0, 3.0])
    emus[1].inject('no_reply', count=3)
    bank.command([4.0, 4.0, 4.0])
    assert wait_for(lambda: bank.fault != '')
    assert 'failed after 3 attempts' in bank.fault
    assert wait_for(lambda: setpoints(emus) == [0.0, 0.0, 0.0])
    assert wait_for(lambda: bank.fault == '')  # y answers again and holds zero
    bank.command([1.0, 1.0, 1.0])
    assert wait_for(lambda: setpoints(emus) == [1.0, 1.0, 1.0])


def test_lost_supply_reconnects_and_is_driven_to_zero_not_its_stale_setpoint(rig, wait_for):
    bank, emus = rig()
    bank.command([2.0, 2.0, 2.0])
    assert wait_for(lambda: setpoints(emus) == [2.0, 2.0, 2.0])
    emus[2].inject('disconnect', duration_s=0.5)
    assert wait_for(lambda: 'link lost' in bank.fault)
    with pytest.raises(CommandRejected, match='fault'):
        bank.command([1.0, 1.0, 1.0])
    assert wait_for(lambda: setpoints(emus)[:2] == [0.0, 0.0])
    assert emus[2].state()['setpoint_a'] == 2.0  # unplugged: the coil keeps its current
    assert wait_for(lambda: bank.fault == '', timeout_s=4.0)
    assert setpoints(emus) == [0.0, 0.0, 0.0]
    assert bank.channels[2].snapshot()['connected']


def test_estop_stops_and_release_needs_a_new_command(rig, wait_for):
    bank, emus = rig()
    bank.command([2.0, -2.0, 2.0])
    assert wait_for(lambda: setpoints(emus) == [2.0, -2.0, 2.0])
    bank.set_estop(True)
    assert wait_for(lambda: setpoints(emus) == [0.0, 0.0, 0.0]
                    and not any(emu.state()['output_on'] for emu in emus))
    with pytest.raises(CommandRejected, match='estop'):
        bank.command([1.0, 1.0, 1.0])
    bank.set_estop(False)
    assert wait_for(lambda: all(emu.state()['output_on'] for emu in emus))
    time.sleep(0.1)
    assert setpoints(emus) == [0.0, 0.0, 0.0]
    bank.command([1.0, 1.0, 1.0])
    assert wait_for(lambda: setpoints(emus) == [1.0, 1.0, 1.0])


def test_shutdown_ramps_to_zero_then_switches_off(rig, wait_for):
    bank, emus = rig(slew_rate_a_per_s=50.0)
    bank.command([5.0, 5.0, -5.0])
    assert wait_for(lambda: setpoints(emus) == [5.0, 5.0, -5.0])
    t0 = time.monotonic()
    assert bank.shutdown() is True
    assert time.monotonic() - t0 >= 5.0 / 50.0 - 2e-3
    assert setpoints(emus) == [0.0, 0.0, 0.0]
    assert not any(emu.state()['output_on'] for emu in emus)
    last_output = [max(e['t'] for e in emu.log if 'output_on' in e) for emu in emus]
    last_set = [max(t for t, _ in set_entries(emu)) for emu in emus]
    assert all(o > s for o, s in zip(last_output, last_set))  # zero first, then off


def test_scpi_exit_reads_back_zero_and_resends_a_lost_last_zero(rig, wait_for):
    bank, emus = rig('scpi', slew_rate_a_per_s=100.0)
    bank.command([4.7, -4.7, 4.7])
    assert wait_for(lambda: setpoints(emus) == [4.7, -4.7, 4.7])
    emus[1].inject('no_reply', count=1, on_current_a=0.0)  # the ramp's last CURR 0 is lost
    assert bank.shutdown() is True
    assert setpoints(emus) == [0.0, 0.0, 0.0]  # read back, not assumed
    assert not any(emu.state()['output_on'] for emu in emus)
    lost = [e for e in emus[1].log if e.get('fault') == 'no_reply']
    assert lost and lost[0]['current_a'] == 0.0


def test_scpi_exit_that_cannot_confirm_zero_says_so_and_names_the_supply(rig, wait_for):
    bank, emus = rig('scpi', slew_rate_a_per_s=100.0)
    bank.command([2.0, 2.0, 2.0])
    assert wait_for(lambda: setpoints(emus) == [2.0, 2.0, 2.0])
    emus[2].inject('no_reply', count=10 ** 6, on_current_a=0.0)  # z never takes zero
    assert bank.shutdown(timeout_s=0.5) is False
    assert len(bank.unsafe) == 1 and bank.unsafe[0].startswith(f'z ({emus[2].port})')
    assert 'holds' in bank.unsafe[0] or 'not confirmed' in bank.unsafe[0]
    assert emus[2].state()['setpoint_a'] != 0.0  # what the message says is true
    assert setpoints(emus)[:2] == [0.0, 0.0]


def test_scpi_lost_set_is_found_on_the_verify_period_whatever_the_readback_rate(rig, wait_for):
    bank, emus = rig('scpi', readback_period_s=10.0)
    bank.command([2.0, 2.0, 2.0])
    assert wait_for(lambda: setpoints(emus) == [2.0, 2.0, 2.0])
    emus[0].inject('no_reply', count=1)  # the next set on x is lost silently
    t_lost = time.monotonic()
    bank.command([3.0, 3.0, 3.0])
    assert wait_for(lambda: setpoints(emus) == [3.0, 3.0, 3.0], timeout_s=2.5)
    assert time.monotonic() - t_lost < 2.5  # one verify period (1 s), not the 10 s readback
    assert [e.get('fault') for e in emus[0].log].count('no_reply') == 1


def test_estop_reports_zero_and_off_only_once_read_back(rig, wait_for):
    bank, emus = rig('scpi', slew_rate_a_per_s=100.0)
    bank.command([3.0, 3.0, 3.0])
    assert wait_for(lambda: setpoints(emus) == [3.0, 3.0, 3.0])
    emus[0].inject('no_reply', count=10 ** 6, on_current_a=0.0)
    bank.set_estop(True)
    time.sleep(0.5)
    level, message = bank.status()
    assert 'not yet confirmed' in message and f'x ({emus[0].port})' in message
    assert 'outputs zero and off' not in message
    # Off is safer than on at any current: after the ramp time and a grace, all switch off.
    assert wait_for(lambda: not any(emu.state()['output_on'] for emu in emus), timeout_s=3.0)
    assert 'not yet confirmed' in bank.status()[1]  # x still holds current: still said


def test_a_port_named_twice_is_logged_as_an_error_at_once(caplog):
    with caplog.at_level('ERROR', logger='tentacle_coils'):
        build_bank(['/dev/a', '/dev/b', '/dev/a'], dialect='dxkdp', baud=9600,
                   max_current_a=1.0, slew_rate_a_per_s=1.0, watchdog_s=1.0)
    assert [r.getMessage() for r in caplog.records] == [
        'ports: supplies x and z both name /dev/a; each needs its own port']


def test_a_supply_found_holding_current_is_ramped_down_not_jumped(emulate, wait_for):
    emus = emulate('dxkdp', baud=115200)
    emus[0].load.drive(setpoint_a=4.0, output_on=True)  # left so by an earlier session
    bank = build_bank([e.port for e in emus], dialect='dxkdp', baud=115200,
                      max_current_a=10.0, slew_rate_a_per_s=40.0, watchdog_s=5.0)
    t0 = time.monotonic()
    bank.start()
    try:
        assert wait_for(lambda: setpoints(emus) == [0.0] * 3
                        and not any(emu.state()['output_on'] for emu in emus))
        steps = [(t0, 4.0)] + set_entries(emus[0], since=t0)
        times, values = np.array(steps).T
        assert len(steps) > 5 and times[-1] - t0 >= 4.0 / 40.0 - 2e-3  # ramped, not jumped
        off = [e['t'] for e in emus[0].log if e.get('output_on') is False]
        assert off and off[0] > times[-1]  # zero first, then off
    finally:
        bank.shutdown(timeout_s=1.0)


def test_measurement_time_is_when_the_oldest_reading_was_asked(rig, wait_for):
    # /coils/field is stamped with this (the closed loop needs the field's age). Check it
    # against when each emulated supply took the read request off its line.
    bank, emus = rig(readback_period_s=0.05)
    bank.command([1.0, -1.0, 0.5])
    assert wait_for(lambda: np.allclose(bank.measured_currents(), [1.0, -1.0, 0.5], atol=0.02))
    wall_minus_monotonic = time.time() - time.monotonic()
    asked = [ch.measured_at_s - wall_minus_monotonic for ch in bank.channels]
    for emu, at in zip(emus, asked):
        reads = [e['t'] for e in emu.log if e.get('command') == 'READ_OUTPUT']
        # The reading asked at `at` is the first read request to arrive after it (the request
        # crosses the modelled 115200-baud line in well under 10 ms).
        first = min(t for t in reads if t >= at - 1e-4)
        assert first - at < 0.01, (first, at)
    assert time.time() - bank.measured_at() < 1.0
    bank.shutdown(timeout_s=1.0)  # no more readings: the channels' times stand still
    assert bank.measured_at() == min(ch.measured_at_s for ch in bank.channels)
