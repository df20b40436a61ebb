"""
Wire codec of the Dexing DXKDP bipolar supplies (binary frames, ACK/NAK).

Taken from public driver code for these units, not from a manual: confirm on your own units.

Request frame: ``AA ADDR CODE LEN DATA... CHK`` where CHK is the low byte of
ADDR + CODE + LEN + sum(DATA). Values are unsigned 16-bit little-endian counts of 0.01 V or
0.01 A; second-generation units take a negative current as the two's complement count.
Every set command is answered by a single byte, ACK (0x06) or NAK (0x15); the two read
commands are answered by a frame of the same shape as the request.

Pure functions, bytes in and values out; the driver (supply.py) and the emulator
(tentacle_sim) share them so they cannot drift apart.
"""

from dataclasses import dataclass
import enum

from tentacle_coils.errors import FrameError

HEADER = 0xAA
ACK = 0x06
NAK = 0x15
VOLTS_PER_COUNT = 0.01
AMPS_PER_COUNT = 0.01
MAX_COUNT = 0xFFFF
MAX_SIGNED_COUNT = 0x7FFF
FRAME_OVERHEAD = 5  # header, address, code, length, checksum


class Code(enum.IntEnum):
    """Command codes."""

    OUTPUT = 0x20
    VOLTAGE = 0x21
    CURRENT = 0x22
    VOLTAGE_CURRENT = 0x23
    POLARITY = 0x24
    READ_OUTPUT = 0x26
    READ_STATE = 0x28


# One row per command: data layout (struct-like: 'B' one byte, 'H' one 16-bit count) and
# whether the device answers with a one-byte ACK/NAK or with a frame of this many data bytes.
@dataclass(frozen=True)
class CommandSpec:
    """Layout of one command's request data and of its reply."""

    layout: str
    reply_data_len: int | None  # None: answered by ACK/NAK


COMMANDS = {
    Code.OUTPUT: CommandSpec('B', None),
    Code.VOLTAGE: CommandSpec('H', None),
    Code.CURRENT: CommandSpec('H', None),
    Code.VOLTAGE_CURRENT: CommandSpec('HH', None),
    Code.POLARITY: CommandSpec('BB', None),
    Code.READ_OUTPUT: CommandSpec('', 5),   # VLO VHI ILO IHI CC
    Code.READ_STATE: CommandSpec('', 5),    # STATE VLO VHI ILO IHI
}


@dataclass(frozen=True)
class Frame:
    """A decoded frame: bus address, command code and data bytes."""

    address: int
    code: int
    data: bytes


@dataclass(frozen=True)
class Reading:
    """What a read command reports: output voltage (V), current (A), state flags."""

    voltage_v: float
    current_a: float
    output_on: bool | None = None
    constant_current: bool | None = None


def checksum(address, code, data):
    """Return the low byte of ADDR + CODE + LEN + sum(DATA)."""
    return (address + code + len(data) + sum(data)) & 0xFF


def encode_frame(address, code, data=b''):
    """
    Return the bytes of one frame.

    :param address: bus address, 0..255
    :param code: command code, 0..255
    :param data: data bytes, at most 255
    :raises ValueError: an address, code or length out of range
    """
    if not 0 <= address <= 0xFF:
        raise ValueError(f'dxkdp address {address} is not in 0..255')
    if not 0 <= code <= 0xFF:
        raise ValueError(f'dxkdp code {code} is not in 0..255')
    data = bytes(data)
    if len(data) > 0xFF:
        raise ValueError(f'dxkdp data of {len(data)} bytes is longer than 255')
    return bytes((HEADER, address, code, len(data))) + data + bytes(
        (checksum(address, code, data),))


def frame_length(buf):
    """Return the total length of the frame starting at buf[0], or None if LEN is not in yet."""
    if len(buf) < 4:
        return None
    return FRAME_OVERHEAD + buf[3]


def decode_frame(buf):
    """
    Decode one whole frame.

    :param buf: exactly one frame's bytes
    :return: the Frame
    :raises FrameError: wrong header, length or checksum
    """
    buf = bytes(buf)
    if len(buf) < FRAME_OVERHEAD or buf[0] != HEADER:
        raise FrameError(f'dxkdp frame {buf.hex(" ")} does not start with AA')
    if len(buf) != FRAME_OVERHEAD + buf[3]:
        raise FrameError(f'dxkdp frame {buf.hex(" ")} has LEN {buf[3]} but '
                         f'{len(buf) - FRAME_OVERHEAD} data bytes')
    address, code, data = buf[1], buf[2], buf[4:-1]
    if checksum(address, code, data) != buf[-1]:
        raise FrameError(f'dxkdp frame {buf.hex(" ")} has a bad checksum '
                         f'(expected {checksum(address, code, data):02x})')
    return Frame(address, code, data)


def _count(value, per_count, what):
    """Return a value as an unsigned count, rounding to the nearest count."""
    if value != value or value in (float('inf'), float('-inf')):
        raise ValueError(f'dxkdp {what} {value} is not finite')
    count = round(value / per_count)
    if not 0 <= count <= MAX_COUNT:
        raise ValueError(f'dxkdp {what} {value} is outside 0..{MAX_COUNT * per_count:g}')
    return count


def current_count(current_a, signed):
    """
    Return the 16-bit count for a current setpoint.

    :param current_a: setpoint, ampere; negative only when ``signed``
    :param signed: second-generation units: a negative current is the two's complement count
    :raises ValueError: not finite, or not representable
    """
    if not signed:
        return _count(current_a, AMPS_PER_COUNT, 'current (A)')
    magnitude = _count(abs(current_a), AMPS_PER_COUNT, 'current (A)')
    if magnitude > MAX_SIGNED_COUNT:
        raise ValueError(f'dxkdp signed current {current_a} A exceeds '
                         f'{MAX_SIGNED_COUNT * AMPS_PER_COUNT:g} A')
    return (0x10000 - magnitude) & 0xFFFF if current_a < 0 else magnitude


def count_to_current(count, signed):
    """Return the current in ampere that a 16-bit count stands for."""
    if signed and count > MAX_SIGNED_COUNT:
        count -= 0x10000
    return count * AMPS_PER_COUNT


def _u16(count):
    return bytes((count & 0xFF, count >> 8))


def _u16_at(data, i):
    return data[i] | (data[i + 1] << 8)


def set_output(address, on):
    """Return the frame that switches the output on or off."""
    return encode_frame(address, Code.OUTPUT, bytes((0x01 if on else 0x00,)))


def set_voltage(address, voltage_v):
    """Return the frame that sets the voltage setpoint (V, >= 0)."""
    return encode_frame(address, Code.VOLTAGE, _u16(_count(voltage_v, VOLTS_PER_COUNT,
                                                           'voltage (V)')))


def set_current(address, current_a, signed=False):
    """Return the frame that sets the current setpoint (A)."""
    return encode_frame(address, Code.CURRENT, _u16(current_count(current_a, signed)))


def set_voltage_current(address, voltage_v, current_a, signed=False):
    """Return the frame that sets voltage (V) and current (A) setpoints together."""
    data = _u16(_count(voltage_v, VOLTS_PER_COUNT, 'voltage (V)')) + _u16(
        current_count(current_a, signed))
    return encode_frame(address, Code.VOLTAGE_CURRENT, data)


def set_polarity(address, voltage_positive, current_positive):
    """Return the frame that sets output polarity (first-generation units)."""
    return encode_frame(address, Code.POLARITY, bytes(
        (0x01 if voltage_positive else 0x00, 0x01 if current_positive else 0x00)))


def read_output(address):
    """Return the frame that asks for measured voltage, current and CC mode."""
    return encode_frame(address, Code.READ_OUTPUT)


def read_state(address):
    """Return the frame that asks for output state, voltage and current."""
    return encode_frame(address, Code.READ_STATE)


def parse_ack(byte):
    """
    Return True for ACK, False for NAK.

    :raises FrameError: any other byte
    """
    if byte == ACK:
        return True
    if byte == NAK:
        return False
    raise FrameError(f'dxkdp expected ACK (06) or NAK (15), got {byte:02x}')


def parse_reading(frame, signed=False):
    """
    Return the Reading carried by a reply to READ_OUTPUT or READ_STATE.

    :param frame: a decoded reply Frame
    :param signed: decode the current as a two's complement count
    :raises FrameError: a frame of another command or length
    """
    spec = COMMANDS.get(frame.code)
    if spec is None or spec.reply_data_len is None:
        raise FrameError(f'dxkdp frame code {frame.code:02x} is not a read reply')
    if len(frame.data) != spec.reply_data_len:
        raise FrameError(f'dxkdp reply {frame.code:02x} has {len(frame.data)} data bytes, '
                         f'expected {spec.reply_data_len}')
    d = frame.data
    if frame.code == Code.READ_OUTPUT:
        return Reading(voltage_v=_u16_at(d, 0) * VOLTS_PER_COUNT,
                       current_a=count_to_current(_u16_at(d, 2), signed),
                       constant_current=bool(d[4]))
    return Reading(voltage_v=_u16_at(d, 1) * VOLTS_PER_COUNT,
                   current_a=count_to_current(_u16_at(d, 3), signed), output_on=bool(d[0]))


def encode_reading(address, code, reading, signed=False):
    """Return a device's reply frame to READ_OUTPUT or READ_STATE (used by emulators)."""
    volts = _u16(_count(abs(reading.voltage_v), VOLTS_PER_COUNT, 'voltage (V)'))
    amps = _u16(current_count(reading.current_a if signed else abs(reading.current_a),
                              signed))
    if code == Code.READ_OUTPUT:
        return encode_frame(address, code, volts + amps + bytes(
            (0x01 if reading.constant_current else 0x00,)))
    if code == Code.READ_STATE:
        return encode_frame(address, code, bytes((0x01 if reading.output_on else 0x00,))
                            + volts + amps)
    raise ValueError(f'dxkdp code {code:#04x} has no reading reply')


def decode_request(frame):
    """
    Return the request's values as a dict with SI names (used by emulators and logs).

    :raises FrameError: an unknown code or a data length that does not fit its layout
    """
    try:
        code = Code(frame.code)
    except ValueError:
        raise FrameError(f'dxkdp unknown command code {frame.code:02x}') from None
    layout = COMMANDS[code].layout
    expected = sum(1 if c == 'B' else 2 for c in layout)
    if len(frame.data) != expected:
        raise FrameError(f'dxkdp {code.name} takes {expected} data bytes, '
                         f'got {len(frame.data)}')
    d = frame.data
    if code == Code.OUTPUT:
        return {'output_on': d[0] == 0x01}
    if code == Code.VOLTAGE:
        return {'voltage_count': _u16_at(d, 0)}
    if code == Code.CURRENT:
        return {'current_count': _u16_at(d, 0)}
    if code == Code.VOLTAGE_CURRENT:
        return {'voltage_count': _u16_at(d, 0), 'current_count': _u16_at(d, 2)}
    if code == Code.POLARITY:
        return {'voltage_positive': d[0] == 0x01, 'current_positive': d[1] == 0x01}
    return {}


def wire_bytes(code):
    """Return (request bytes, reply bytes) of one exchange of this command."""
    spec = COMMANDS[Code(code)]
    request = FRAME_OVERHEAD + sum(1 if c == 'B' else 2 for c in spec.layout)
    reply = 1 if spec.reply_data_len is None else FRAME_OVERHEAD + spec.reply_data_len
    return request, reply
