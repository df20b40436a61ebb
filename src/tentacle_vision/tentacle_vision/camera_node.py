"""
camera_node: frames from a capture device, a video file or a folder of images, on ROS.

Publishes /camera/image_raw (sensor_msgs/Image, ``encoding`` bgr8 or mono8; the latest two,
reliable) and /camera/camera_info (sensor_msgs/CameraInfo: the frame's size) at the
source's own rate or ``rate``, stamped when each frame is read. A folder replays a recorded
run in name order (``wait_for_subscriber`` holds it until someone listens); ``loop`` starts a
video or folder again at its end, otherwise the node
says the source has ended (diagnostics) and publishes nothing more. Sources, and where a
Basler or GenICam camera plugs in: tentacle_vision.sources (no rclpy).
"""

import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from tentacle_common import contract
from tentacle_common.driver_node import (declare_parameters, diagnostic_status, publisher,
                                         run_node)
from tentacle_common.errors import ConfigError
from tentacle_vision import image_codec
from tentacle_vision.params import CAMERA_NODE, CAMERA_PARAMS
from tentacle_vision.sources import as_encoding, ENCODINGS, FOLDER_RATE_HZ, open_source


class CameraNode(Node):
    """Reads frames on a thread of its own and publishes them."""

    def __init__(self):
        """Open the source, wire the publishers, start reading."""
        super().__init__(CAMERA_NODE)
        p = declare_parameters(self, CAMERA_PARAMS)
        if p['encoding'] not in ENCODINGS:
            raise ConfigError(f"encoding {p['encoding']!r} is not one of {ENCODINGS}")
        try:
            self.source = open_source(p['source'], p['loop'])
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        self.encoding, self.frame_id, self.spec = p['encoding'], p['frame_id'], p['source']
        self.rate_hz = p['rate'] or self.source.rate_hz or FOLDER_RATE_HZ
        self.wait_for_subscriber = p['wait_for_subscriber']
        self.image_pub = publisher(self, contract.IMAGE)
        self.info_pub = publisher(self, contract.CAMERA_INFO)
        self.diag_pub = publisher(self, contract.DIAGNOSTICS)
        self.create_timer(1.0, self.publish_diagnostics)
        self.frames, self.ended, self.problem = 0, False, ''
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='camera', daemon=True)
        self._thread.start()

    def _run(self):
        while self.wait_for_subscriber and self.image_pub.get_subscription_count() == 0:
            if self._stop.wait(0.05):
                return
        period = 1.0 / self.rate_hz
        next_at = time.monotonic()
        while not self._stop.is_set():
            try:
                frame = self.source.read()
            except ValueError as exc:
                self.problem = str(exc)
                self.get_logger().error(str(exc), throttle_duration_sec=5.0)
                frame = None
            if frame is None:
                self.ended = True
                self.get_logger().info(f'{self.spec}: source ended after {self.frames} frames')
                return
            self.publish(as_encoding(frame, self.encoding))
            next_at += period
            self._stop.wait(max(next_at - time.monotonic(), 0.0))
            next_at = max(next_at, time.monotonic() - period)  # behind: do not catch up

    def publish(self, frame):
        """Publish one frame and its camera info, stamped now."""
        height, width, step, data = image_codec.to_message(frame, self.encoding)
        msg = Image(height=height, width=width, encoding=self.encoding, step=step, data=data)
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.frame_id
        self.image_pub.publish(msg)
        self.info_pub.publish(CameraInfo(header=msg.header, height=height, width=width))
        self.frames += 1

    def publish_diagnostics(self):
        """Publish one status: streaming, ended, or a source problem."""
        if self.problem:
            level, message = 'error', self.problem
        elif self.ended:
            level, message = 'warn', f'source ended after {self.frames} frames'
        else:
            level, message = 'ok', f'streaming at {self.rate_hz:g} Hz'
        msg = DiagnosticArray(status=[diagnostic_status(
            f'{CAMERA_NODE}: source', self.spec, level, message,
            {'frames': self.frames, 'rate_hz': self.rate_hz, 'encoding': self.encoding})])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)

    def shutdown(self):
        """Stop reading and release the source."""
        self._stop.set()
        self._thread.join(2.0)
        self.source.close()
        return f'stopped after {self.frames} frames'


def main(args=None):
    """Run the node until a signal."""
    run_node(sys.argv[1:] if args is None else list(args), CAMERA_NODE, CAMERA_PARAMS,
             __doc__, CameraNode, lambda node: node.shutdown())


if __name__ == '__main__':
    main()
