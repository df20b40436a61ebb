"""
The header stamp of a serialized ROS 2 message, read without deserializing the message.

A subscriber that needs a message only now and then (a closed loop taking the frames after
its last command; a 30 Hz centreline of hundreds of poses costs milliseconds to
deserialize in Python) takes it serialized and reads the stamp first: every message whose
first field is a std_msgs/Header starts, after CDR's 4-byte encapsulation header, with the
stamp's int32 seconds and uint32 nanoseconds. Pure: no rclpy.
"""

import struct

_ENDIAN = {0x00: '>', 0x01: '<'}   # CDR_BE, CDR_LE (the encapsulation's second byte)


def header_stamp_s(raw):
    """
    Return the header stamp (s) of a serialized message that begins with a std_msgs/Header.

    :raises ValueError: not CDR encapsulated, or too short to hold a stamp
    """
    if len(raw) < 12 or raw[0] != 0 or raw[1] not in _ENDIAN:
        raise ValueError('not a CDR-encapsulated message with a header')
    sec, nanosec = struct.unpack_from(_ENDIAN[raw[1]] + 'iI', raw, 4)
    return sec + 1e-9 * nanosec
