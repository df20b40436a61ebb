"""The header stamp read from serialized bytes is the one rclpy serialized."""

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Header
from tentacle_common.cdr import header_stamp_s


@pytest.mark.parametrize('sec, nanosec', [(0, 0), (1796310585, 928032757), (-3, 999999999)])
def test_the_stamp_of_a_serialized_path_and_pose(sec, nanosec):
    header = Header(frame_id='workspace')
    header.stamp.sec, header.stamp.nanosec = sec, nanosec
    for msg in (Path(header=header, poses=[PoseStamped(header=header)] * 3),
                PoseStamped(header=header)):
        assert header_stamp_s(serialize_message(msg)) == pytest.approx(sec + 1e-9 * nanosec,
                                                                       abs=1e-9)


def test_bytes_that_are_not_cdr_are_refused():
    with pytest.raises(ValueError, match='not a CDR'):
        header_stamp_s(b'\x07\x07' + bytes(20))
    with pytest.raises(ValueError, match='not a CDR'):
        header_stamp_s(b'\x00\x01\x00')
