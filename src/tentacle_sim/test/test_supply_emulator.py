"""The emulator seen from the wire: raw bytes in, raw bytes out, over a real pty."""

import os
import select
import time

import pytest

from tentacle_coils import dxkdp, scpi
from tentacle_sim.supply_emulator import make_supply


def exchange(fd, request, reply_len=None, timeout_s=1.0):
    """Write request; return (reply bytes, seconds until the reply was complete)."""
    t0 = time.monotonic()
    os.write(fd, request)
    out = b''
    deadline = t0 + timeout_s
    while time.monotonic() < deadline:
        if reply_len is not None and len(out) >= reply_len:
            break
        if reply_len is None and out.endswith(b'\n'):
            break
        readable, _, _ = select.select([fd], [], [], deadline - time.monotonic())
        if readable:
            out += os.read(fd, 256)
    return out, time.monotonic() - t0


@pytest.fixture
def open_port(on_pty, tmp_path):
    return lambda dialect, **kwargs: on_pty(make_supply, 'x', dialect,
                                            log_path=str(tmp_path / 'x.jsonl'), **kwargs)


def test_dxkdp_set_is_acked_and_paced_at_baud(open_port):
    emu, fd = open_port('dxkdp', baud=9600, delay_s=0.0)
    reply, elapsed = exchange(fd, dxkdp.set_current(1, 2.5, signed=True), 1)
    assert reply == bytes((dxkdp.ACK,))
    assert elapsed >= 8 * 10 / 9600  # 7 request bytes + 1 reply byte at 9600 baud
    assert emu.state()['setpoint_a'] == 2.5
    assert emu.log[-1]['command'] == 'CURRENT' and emu.log[-1]['current_a'] == 2.5


def test_dxkdp_read_output_reports_the_coil(open_port):
    emu, fd = open_port('dxkdp', baud=115200)
    exchange(fd, dxkdp.set_output(1, True), 1)
    exchange(fd, dxkdp.set_current(1, -1.25, signed=True), 1)
    time.sleep(0.1)  # ten L/R time constants of the default coil
    reply, _ = exchange(fd, dxkdp.read_output(1), 10)
    reading = dxkdp.parse_reading(dxkdp.decode_frame(reply), signed=True)
    assert reading.current_a == pytest.approx(-1.25, abs=0.01)


def test_dxkdp_first_generation_polarity_by_command(open_port):
    emu, fd = open_port('dxkdp', baud=115200, polarity_mode='command')
    assert exchange(fd, dxkdp.set_polarity(1, False, False), 1)[0] == b'\x06'
    assert exchange(fd, dxkdp.set_current(1, 3.0), 1)[0] == b'\x06'
    assert emu.state()['setpoint_a'] == -3.0


def test_dxkdp_bad_checksum_other_address_and_rating(open_port):
    emu, fd = open_port('dxkdp', baud=115200, max_current_a=10.0)
    frame = bytearray(dxkdp.set_current(1, 1.0))
    frame[-1] ^= 0xFF
    assert exchange(fd, bytes(frame), 1)[0] == b'\x15'
    assert exchange(fd, dxkdp.set_current(2, 1.0), 1, timeout_s=0.1)[0] == b''
    assert exchange(fd, dxkdp.set_current(1, 11.0), 1)[0] == b'\x15'
    assert emu.state()['setpoint_a'] == 0.0


@pytest.mark.parametrize('kind, expected', [('nak', b'\x15'), ('garble', b'\x5a'),
                                            ('no_reply', b'')])
def test_dxkdp_injected_faults(open_port, kind, expected):
    emu, fd = open_port('dxkdp', baud=115200)
    emu.inject(kind, count=1)
    assert exchange(fd, dxkdp.set_current(1, 1.0), 1, timeout_s=0.1)[0] == expected
    assert exchange(fd, dxkdp.set_current(1, 1.0), 1)[0] == b'\x06'  # count was 1


def test_late_reply_is_late(open_port):
    emu, fd = open_port('dxkdp', baud=115200)
    emu.inject('late', count=1, late_s=0.15)
    reply, elapsed = exchange(fd, dxkdp.set_current(1, 1.0), 1)
    assert reply == b'\x06' and elapsed >= 0.15


def test_scpi_session_and_error_queue(open_port):
    emu, fd = open_port('scpi', baud=115200)
    assert scpi.parse_identity(exchange(fd, scpi.identify())[0])[0] == 'Emulated'
    os.write(fd, scpi.set_current(-2.0) + scpi.set_output(True))
    assert scpi.parse_float(exchange(fd, scpi.query_setpoint())[0]) == -2.0
    assert scpi.parse_bool(exchange(fd, scpi.query_output())[0]) is True
    os.write(fd, b'VOLT 3\n')
    exchange(fd, scpi.query_output())  # the emulator has served VOLT once this answers
    emu.inject('error', count=1, code=-300, text='Device-specific error')
    assert scpi.parse_error(exchange(fd, scpi.query_error())[0]) == scpi.UNDEFINED_HEADER
    assert scpi.parse_error(exchange(fd, scpi.query_error())[0]) == (-300,
                                                                     'Device-specific error')
    assert scpi.parse_error(exchange(fd, scpi.query_error())[0]) == scpi.NO_ERROR


@pytest.mark.parametrize('kind', ['garble', 'late'])
def test_a_reply_fault_waits_for_a_request_that_is_answered(open_port, kind):
    # A SCPI set has no reply: a reply fault armed before it used to be spent on it (the set
    # was applied, nothing was garbled, and the log tagged it as faulted).
    emu, fd = open_port('scpi', baud=115200)
    emu.inject(kind, count=1, late_s=0.2)
    os.write(fd, scpi.set_current(1.5))
    reply, elapsed = exchange(fd, scpi.query_setpoint(), timeout_s=0.5)
    sets = [e for e in emu.log if e.get('command') == 'CURR']
    assert sets and 'fault' not in sets[0] and emu.state()['setpoint_a'] == 1.5
    assert [e.get('fault') for e in emu.log if e.get('command') == 'CURR?'] == [kind]
    assert emu.pending_faults() == {}
    if kind == 'late':
        assert scpi.parse_float(reply) == 1.5 and elapsed >= 0.2
    else:
        assert reply != scpi.format_value(1.5)


def test_disconnect_removes_the_port_then_restores_it_with_the_current_kept(open_port):
    emu, fd = open_port('dxkdp', baud=115200)
    exchange(fd, dxkdp.set_output(1, True), 1)
    exchange(fd, dxkdp.set_current(1, 4.0, signed=True), 1)
    emu.inject('disconnect', duration_s=0.3)
    time.sleep(0.1)
    assert not os.path.exists(emu.link_path)
    with pytest.raises(OSError):
        os.write(fd, dxkdp.read_state(1))
        os.read(fd, 16)
    time.sleep(0.4)
    assert os.path.exists(emu.link_path) and emu.state()['setpoint_a'] == 4.0


def test_log_file_holds_every_request(open_port, tmp_path):
    emu, fd = open_port('dxkdp', baud=115200)
    for current_a in (0.5, 1.5):
        exchange(fd, dxkdp.set_current(1, current_a, signed=True), 1)
    lines = (tmp_path / 'x.jsonl').read_text().splitlines()
    assert [line for line in lines if '"CURRENT"' in line] and len(lines) == 2
