"""recorder_node's parameters, in one table (plain data, no rclpy)."""

from tentacle_common.params import Param

NODE_NAME = 'recorder_node'
IMAGE_FORMATS = ('jpeg', 'png')

RECORDER_PARAMS = (
    Param('out', '', 'the bag directory to write (metadata.yaml and one MCAP file); it must '
          'not exist (empty: /tmp/tentacle_rig/bags/<date-time>)'),
    Param('image_rate', 2.0, 'camera frames recorded per second at most (0: none); every '
          'other topic is recorded whole, hertz', 0.0, 120.0),
    Param('image_format', 'jpeg', 'camera frames as sensor_msgs/CompressedImage on '
          '/camera/image_raw/compressed: jpeg (lossy, small) or png (lossless)'),
    Param('image_scale', 0.5, 'each side of a recorded frame scaled by this (0.5: a quarter '
          'of the pixels)', 0.05, 1.0),
    Param('jpeg_quality', 90, 'JPEG quality, 1 (smallest) to 100', 1, 100),
)
