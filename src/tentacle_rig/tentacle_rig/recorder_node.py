"""
recorder_node: record the rig's topics into a rosbag2 directory (MCAP), closed on exit.

Every topic of the contract (tentacle_common.contract) is recorded whole as it arrives (its
serialized bytes, its receive time), except the camera's frames: at most ``image_rate`` a
second, each side scaled by ``image_scale``, as sensor_msgs/CompressedImage on
/camera/image_raw/compressed (``image_format`` jpeg or png, as image_transport's compressed
frames; Foxglove shows them). /vision/debug_image
is not recorded. Ctrl-C or SIGTERM closes the bag: metadata.yaml is written and the MCAP
file finished, readable by ``ros2 bag``, Foxglove and tentacle_rig.recording.read_bag.
"""

import sys
import time

import cv2
from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CompressedImage, Image
from tentacle_common import contract
from tentacle_common.driver_node import (declare_parameters, diagnostic_status, interface,
                                         publisher, qos_profile, run_node)
from tentacle_common.errors import ConfigError
from tentacle_rig.recorder_params import IMAGE_FORMATS, NODE_NAME, RECORDER_PARAMS
from tentacle_rig.recording import FrameGate, Recording

STATUS_PERIOD_S = 0.2   # /diagnostics: which topics have a publisher matched


def recorded_topics():
    """Return the contract topics a run's recording holds."""
    rows = [v for v in vars(contract).values() if isinstance(v, contract.Topic)
            and v is not contract.VISION_DEBUG]
    for axis in contract.AXES:
        rows += [contract.axis_target(axis), contract.axis_state(axis)]
    return rows


class RecorderNode(Node):
    """Subscribe to every recorded topic; write each message as it comes."""

    def __init__(self):
        """Open the bag and subscribe."""
        super().__init__(NODE_NAME)
        p = declare_parameters(self, RECORDER_PARAMS)
        if p['image_format'] not in IMAGE_FORMATS:
            raise ConfigError(f'image_format: {p["image_format"]!r} is not one of '
                              f'{", ".join(IMAGE_FORMATS)}')
        out = p['out'] or f'/tmp/tentacle_rig/bags/{time.strftime("%Y%m%d-%H%M%S")}'
        topics = recorded_topics()
        if p['image_rate'] <= 0:   # no frames: not even received (3 MB each, 30 a second)
            topics = [t for t in topics if t.msg_type != 'sensor_msgs/msg/Image']
        try:
            self.recording = Recording(out, topics)
        except (FileExistsError, OSError) as exc:
            raise ConfigError(f'out: {exc}') from None
        self.format, self.quality = p['image_format'], p['jpeg_quality']
        self.scale = p['image_scale']
        self.gate = FrameGate(p['image_rate'])
        self._refused_encodings = set()
        self.subscriptions_by_topic = {}
        for topic in topics:   # serialized: a frame is only deserialized when it is kept
            handler = self.on_image if topic.msg_type == 'sensor_msgs/msg/Image' else \
                self.on_raw
            self.subscriptions_by_topic[topic.name] = self.create_subscription(
                interface(topic.msg_type), topic.name,
                lambda raw, t=topic, h=handler: h(t, raw), qos_profile(topic.qos), raw=True)
        self.diag_pub = publisher(self, contract.DIAGNOSTICS)
        self.create_timer(STATUS_PERIOD_S, self.publish_status)
        self.get_logger().info(f'recording {len(topics)} topics into {out} (camera frames '
                               f'as {self.format} at most {p["image_rate"]:g} Hz, scaled '
                               f'{self.scale:g})')

    def publish_status(self):
        """Say what is recorded: the topics with a publisher matched (a run may start)."""
        matched = sorted(name for name, sub in self.subscriptions_by_topic.items()
                         if sub.get_publisher_count() > 0)
        values = {'bag': str(self.recording.path), 'matched': ','.join(matched),
                  'messages': sum(self.recording.counts.values())}
        msg = DiagnosticArray(status=[diagnostic_status(
            f'{NODE_NAME}: bag', NODE_NAME, 'ok', f'recording {len(matched)} topics', values)])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)

    def now_ns(self):
        """Return the ROS clock now, ns."""
        return self.get_clock().now().nanoseconds

    def on_raw(self, topic, raw):
        """Write one serialized message."""
        self.recording.write(topic.name, self.now_ns(), raw)

    def on_image(self, topic, raw):
        """Write a frame, scaled and compressed, when the gate lets it through."""
        now = self.now_ns()
        if not self.gate.passes(now * 1e-9):
            return
        msg = deserialize_message(raw, Image)
        try:
            data = encode(msg, self.format, self.quality, self.scale)
        except ValueError as exc:   # said once per encoding; the other topics go on
            if msg.encoding not in self._refused_encodings:
                self._refused_encodings.add(msg.encoding)
                self.get_logger().error(f'{topic.name}: {exc}')
            return
        compressed = CompressedImage(header=msg.header, data=data)
        compressed.format = f'{msg.encoding}; {self.format} compressed {msg.encoding}'
        self.recording.write(topic.name, now, serialize_message(compressed))

    def shutdown(self):
        """Close the bag; return the line said at exit."""
        counts = self.recording.close()
        return (f'recording closed: {self.recording.path} ({sum(counts.values())} messages, '
                f'{counts.get(contract.IMAGE.name, 0)} frames)')


def encode(msg: Image, fmt, quality, scale=1.0):
    """Return a mono8 or bgr8/rgb8 Image's bytes as JPEG or PNG, each side scaled."""
    channels = {'mono8': 1, 'bgr8': 3, 'rgb8': 3}.get(msg.encoding)
    if channels is None:
        raise ValueError(f'frames of encoding {msg.encoding!r} are not recorded')
    pixels = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(
        msg.height, msg.step)[:, :msg.width * channels].reshape(msg.height, msg.width, channels)
    if msg.encoding == 'rgb8':
        pixels = pixels[..., ::-1]
    if scale != 1.0:
        pixels = cv2.resize(pixels, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    if fmt == 'jpeg':
        ok, data = cv2.imencode('.jpg', pixels, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    else:
        ok, data = cv2.imencode('.png', pixels)
    if not ok:
        raise ValueError(f'the frame could not be encoded as {fmt}')
    return data.tobytes()


def main(args=None):
    """Run the node; on exit the bag is closed."""
    argv = sys.argv[1:] if args is None else args
    run_node(argv, NODE_NAME, RECORDER_PARAMS, __doc__, RecorderNode, RecorderNode.shutdown)


if __name__ == '__main__':
    main()
