"""Byte-exact tests of the DXKDP codec (frames worked out by hand from DESIGN.md)."""

import pytest

from tentacle_coils import dxkdp
from tentacle_coils.errors import FrameError


@pytest.mark.parametrize('frame, expected', [
    (dxkdp.set_output(1, True), 'aa 01 20 01 01 23'),
    (dxkdp.set_output(1, False), 'aa 01 20 01 00 22'),
    (dxkdp.set_current(1, 2.0), 'aa 01 22 02 c8 00 ed'),
    (dxkdp.set_current(1, -1.5, signed=True), 'aa 01 22 02 6a ff 8e'),
    (dxkdp.set_voltage(3, 12.34), 'aa 03 21 02 d2 04 fc'),
    (dxkdp.set_voltage_current(1, 30.0, 10.0), 'aa 01 23 04 b8 0b e8 03 d6'),
    (dxkdp.set_polarity(1, True, False), 'aa 01 24 02 01 00 28'),
    (dxkdp.read_output(2), 'aa 02 26 00 28'),
    (dxkdp.read_state(1), 'aa 01 28 00 29'),
])
def test_request_frames_are_byte_exact(frame, expected):
    assert frame.hex(' ') == expected


def test_checksum_wraps_to_low_byte():
    frame = dxkdp.set_current(0xFF, 655.35)  # count 0xFFFF
    assert frame.hex(' ') == 'aa ff 22 02 ff ff ' + f'{(0xFF + 0x22 + 2 + 0xFF + 0xFF) & 0xFF:02x}'


def test_current_rounds_to_nearest_count():
    assert dxkdp.current_count(1.234, signed=False) == 123
    assert dxkdp.current_count(1.235001, signed=False) == 124


@pytest.mark.parametrize('current_a, signed', [
    (-0.01, False), (655.36, False), (327.68, True), (float('nan'), False),
    (float('inf'), True)])
def test_unrepresentable_currents_raise(current_a, signed):
    with pytest.raises(ValueError):
        dxkdp.set_current(1, current_a, signed=signed)


def test_signed_count_round_trips():
    for current_a in (-327.67, -1.5, -0.01, 0.0, 0.01, 2.0, 327.67):
        count = dxkdp.current_count(current_a, signed=True)
        assert dxkdp.count_to_current(count, signed=True) == pytest.approx(current_a)


def test_decode_frame_round_trip_and_request_values():
    frame = dxkdp.decode_frame(dxkdp.set_voltage_current(7, 30.0, 10.0))
    assert (frame.address, frame.code) == (7, dxkdp.Code.VOLTAGE_CURRENT)
    assert dxkdp.decode_request(frame) == {'voltage_count': 3000, 'current_count': 1000}
    frame = dxkdp.decode_frame(dxkdp.set_polarity(1, False, True))
    assert dxkdp.decode_request(frame) == {'voltage_positive': False, 'current_positive': True}


@pytest.mark.parametrize('raw, reason', [
    ('ab 01 22 02 c8 00 ed', 'AA'),
    ('aa 01 22 02 c8 00 ee', 'checksum'),
    ('aa 01 22 03 c8 00 ed', 'LEN'),
])
def test_garbled_frames_raise(raw, reason):
    with pytest.raises(FrameError, match=reason):
        dxkdp.decode_frame(bytes.fromhex(raw))


def test_unknown_code_and_wrong_length_are_named():
    with pytest.raises(FrameError, match='unknown command code 30'):
        dxkdp.decode_request(dxkdp.decode_frame(dxkdp.encode_frame(1, 0x30, b'')))
    with pytest.raises(FrameError, match='CURRENT takes 2 data bytes'):
        dxkdp.decode_request(dxkdp.decode_frame(dxkdp.encode_frame(1, 0x22, b'\x01')))


def test_read_output_reply_decodes():
    # AA 01 26 05 VLO VHI ILO IHI CC CHK: 12.00 V, 3.45 A, constant current.
    raw = dxkdp.encode_frame(1, 0x26, bytes((0xB0, 0x04, 0x59, 0x01, 0x01)))
    reading = dxkdp.parse_reading(dxkdp.decode_frame(raw))
    assert reading.voltage_v == pytest.approx(12.0)
    assert reading.current_a == pytest.approx(3.45)
    assert reading.constant_current is True


def test_read_state_reply_decodes_signed_current():
    reading = dxkdp.Reading(voltage_v=5.0, current_a=-2.5, output_on=True)
    raw = dxkdp.encode_reading(1, dxkdp.Code.READ_STATE, reading, signed=True)
    checksum = (1 + 0x28 + 5 + 1 + 0xF4 + 1 + 6 + 0xFF) & 0xFF
    assert raw.hex(' ') == f'aa 01 28 05 01 f4 01 06 ff {checksum:02x}'
    back = dxkdp.parse_reading(dxkdp.decode_frame(raw), signed=True)
    assert (back.output_on, back.voltage_v, back.current_a) == (True, 5.0, -2.5)


def test_ack_nak_and_other_bytes():
    assert dxkdp.parse_ack(0x06) is True
    assert dxkdp.parse_ack(0x15) is False
    with pytest.raises(FrameError, match='got 07'):
        dxkdp.parse_ack(0x07)


def test_frame_length_from_partial_buffer():
    assert dxkdp.frame_length(b'\xaa\x01') is None
    assert dxkdp.frame_length(b'\xaa\x01\x26\x05') == 10


def test_wire_bytes_of_set_and_read():
    assert dxkdp.wire_bytes(dxkdp.Code.CURRENT) == (7, 1)
    assert dxkdp.wire_bytes(dxkdp.Code.READ_OUTPUT) == (5, 10)
