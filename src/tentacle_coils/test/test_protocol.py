"""
Protocol tests: the drivers against scripted exchanges on a virtual clock.

Each test lists the exact bytes the driver must send and what the device answers, and
when; the line fails on any other request and on anything left over. Timing comes from the
script, not from this machine, so late replies and slew timing are tested exactly.
"""

import math

import pytest

from tentacle_coils import dxkdp, scpi
from tentacle_coils.coil_bank import Channel
from tentacle_coils.errors import SupplyFault
from tentacle_coils.supply import make_supply
from tentacle_common.scripted_line import Exchange, ScriptedLine, ScriptError

ACK, NAK = bytes((dxkdp.ACK,)), bytes((dxkdp.NAK,))
BAUD = 9600


def dxkdp_supply(script, **kwargs):
    line = ScriptedLine(script, baud=BAUD)
    line.open()
    options = {'retries': 3, 'reply_timeout_s': 0.1, 'max_turnaround_s': 0.25, **kwargs}
    return make_supply('dxkdp', line, **options), line


def state_frame(current_a, output_on=True, voltage_v=30.0):
    reading = dxkdp.Reading(voltage_v=voltage_v, current_a=current_a, output_on=output_on)
    return dxkdp.encode_reading(1, dxkdp.Code.READ_STATE, reading, signed=True)


SET_6A = dxkdp.set_current(1, 6.0, signed=True)
READ_STATE = dxkdp.read_state(1)


def test_the_script_itself_fails_on_a_wrong_request_and_on_leftovers():
    supply, line = dxkdp_supply([Exchange(SET_6A, ACK)])
    with pytest.raises(ScriptError, match='the script expects aa 01 22'):
        supply.set_current(5.0)
    supply, line = dxkdp_supply([Exchange(SET_6A, ACK + ACK)])
    supply.set_current(6.0)
    with pytest.raises(ScriptError, match='reply bytes never read: 06'):
        line.finish()


def test_a_clean_ack_is_trusted_without_a_read_back():
    supply, line = dxkdp_supply([Exchange(SET_6A, ACK)])
    supply.set_current(6.0)
    line.finish()
    assert supply.counters['retries'] == 0


def test_a_late_ack_is_drained_and_the_refusal_of_the_retries_is_seen():
    # The device answers the first set 0.3 s late (ACK), then refuses every retry (NAK).
    # Waiting 25 ms before retrying took the late ACK for the answer to a retry.
    supply, line = dxkdp_supply([Exchange(SET_6A, ACK, after_s=0.3)]
                                + [Exchange(SET_6A, NAK)] * 3)
    with pytest.raises(SupplyFault, match='CURRENT failed after 4 attempts.*NAK'):
        supply.set_current(6.0)
    line.finish()
    assert supply.counters['stale_bytes'] == 1 and supply.counters['refusals'] == 3
    late_ack_at = line.sent[0][0] + 0.3
    assert line.sent[1][0] > late_ack_at + 0.25  # the retry waited for a quiet line


def test_a_set_that_succeeds_after_a_timeout_is_confirmed_by_reading_the_state_back():
    supply, line = dxkdp_supply([Exchange(SET_6A, ACK, after_s=0.3), Exchange(SET_6A, ACK),
                                 Exchange(READ_STATE, state_frame(6.0))])
    supply.set_current(6.0)
    line.finish()
    assert supply.counters['timeouts'] == 1 and supply.counters['unconfirmed'] == 0


def test_an_ack_later_than_the_worst_turnaround_is_caught_by_the_read_back():
    # The first ACK comes 0.36 s late, after the drain: it is read as the retry's answer.
    # The retry itself was refused (NAK), and the state read back shows 1 A, not 6 A: the
    # set counts as failed, is retried, is refused again, and the supply is faulted.
    supply, line = dxkdp_supply([
        Exchange(SET_6A, ACK, after_s=0.36),
        Exchange(SET_6A, NAK),
        Exchange(READ_STATE, state_frame(1.0)),  # its head is read behind the stray NAK
        Exchange(READ_STATE, state_frame(1.0)),
        Exchange(SET_6A, NAK),
        Exchange(SET_6A, NAK)])
    with pytest.raises(SupplyFault, match='NAK'):
        supply.set_current(6.0)
    line.finish()
    assert supply.counters['unconfirmed'] == 1


def test_a_late_read_reply_is_not_taken_for_the_next_read():
    stale = dxkdp.encode_reading(1, dxkdp.Code.READ_OUTPUT,
                                 dxkdp.Reading(voltage_v=5.0, current_a=5.0,
                                               constant_current=True), signed=True)
    fresh = dxkdp.encode_reading(1, dxkdp.Code.READ_OUTPUT,
                                 dxkdp.Reading(voltage_v=1.0, current_a=1.0,
                                               constant_current=True), signed=True)
    read = dxkdp.read_output(1)
    supply, line = dxkdp_supply([Exchange(read, stale, after_s=0.3), Exchange(read, fresh)])
    assert supply.read_current() == pytest.approx(1.0)
    line.finish()


def scpi_channel(responder, slew_a_per_s, baud=BAUD):
    line = ScriptedLine(baud=baud, responder=responder)
    line.open()
    supply = make_supply('scpi', line, retries=1, reply_timeout_s=0.05)
    channel = Channel('x', supply, slew_rate_a_per_s=slew_a_per_s, readback_period_s=0.05)
    channel.connected = True
    channel.output_on = channel.output_wanted = True
    channel.confirmed = True
    return channel, line


class ScpiDevice:
    """A protocol-level SCPI supply: holds a setpoint, answers queries at once."""

    def __init__(self):
        self.setpoint_a = 0.0

    def __call__(self, request):
        header, argument, _ = scpi.parse_command(request)
        if header == 'CURR':
            self.setpoint_a = float(argument)
            return b'', 0.0
        replies = {'CURR?': scpi.format_value(self.setpoint_a),
                   'MEAS:CURR?': scpi.format_value(self.setpoint_a), 'OUTP?': b'1\n',
                   'SYST:ERR?': scpi.format_error(*scpi.NO_ERROR)}
        return replies[header], 0.0005


@pytest.mark.parametrize('dialect', ['scpi', 'dxkdp'])
def test_streamed_commands_never_change_the_setpoint_faster_than_the_slew_rate(dialect):
    # Targets arrive faster than the line can carry them, readbacks and read-backs are
    # interleaved: every set must differ from the one before it by at most slew_rate times
    # the time between their arrivals at the device (their last bytes leaving the line).
    slew = 200.0
    if dialect == 'scpi':
        channel, line = scpi_channel(ScpiDevice(), slew)
    else:
        line = ScriptedLine(baud=BAUD, responder=lambda request: (
            ACK if request[2] != dxkdp.Code.READ_OUTPUT else dxkdp.encode_reading(
                1, dxkdp.Code.READ_OUTPUT, dxkdp.Reading(0.0, 0.0, constant_current=True),
                signed=True), 0.0005))
        line.open()
        supply = make_supply('dxkdp', line)
        channel = Channel('x', supply, slew_rate_a_per_s=slew, readback_period_s=0.05)
        channel.connected = channel.confirmed = True
        channel.output_on = channel.output_wanted = True
    t_end = 2.0
    while line.now() < t_end:
        # A new target every 0.2 ms: a saw tooth between -3 A and +3 A every 0.1 s.
        channel.request(target_a=3.0 * math.sin(2 * math.pi * line.now() / 0.1))
        line.advance(2e-4)
        channel._serve()
    sets = [(t, scpi.parse_float(data[5:]) if dialect == 'scpi' else
             dxkdp.count_to_current(data[4] | data[5] << 8, True))
            for t, data in line.sent if data.startswith(b'CURR ') or (
                dialect == 'dxkdp' and data[2] == dxkdp.Code.CURRENT)]
    assert len(sets) > 50
    worst = max(abs(v1 - v0) / (t1 - t0) for (t0, v0), (t1, v1) in zip(sets, sets[1:]))
    resolution = channel.supply.resolution_a
    assert worst <= slew * (1 + 1e-9) + resolution / min(t1 - t0 for (t0, _), (t1, _) in zip(
        sets, sets[1:])), f'{worst:.1f} A/s at the wire, slew_rate {slew} A/s'
