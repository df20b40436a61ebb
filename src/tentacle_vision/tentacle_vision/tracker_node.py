"""
tracker_node: the tentacle's tip and shape from camera frames, at camera rate.

Subscribes ``image_topic`` (sensor_msgs/Image: mono8, bgr8, rgb8, bayer_rggb8; the latest
two frames, reliable unless ``image_reliability`` is best_effort, so a slow moment drops
frames instead of queueing them). For each frame it publishes,
with the frame's own header stamp and frame ``workspace``:

- /vision/tip (geometry_msgs/PoseStamped): the tip, m; heading as a rotation about z
- /vision/shape (nav_msgs/Path): the centreline, base to tip, m
- /vision/loop (sensor_msgs/JointState): when the body has closed on itself, instead of a
  tip: ``name`` ['centre_x', 'centre_y', 'radius', 'turned'], ``position`` [m, m, m, rad]
  (a turn past a full circle hides under the body: the turn seen)
- /vision/debug_image (sensor_msgs/Image, bgr8) at ``debug_rate``, scaled by ``debug_scale``
- /diagnostics: tracking, loop or lost (and why), processing time, frames and losses.

With ``background_image`` (a frame of the scene without the tentacle), the body is what
differs from it, colour included: the inserter's sheath, the phantom's walls, fluid and
glare are in both frames and stay out of the body. /vision/capture_background
(std_srvs/Trigger) takes the latest frame as that background, writes it to
``background_image`` (or /tmp/tentacle_background.png when none is set) and uses it from
the next frame: call it with nothing inserted. A ``background_image`` that is not there yet
is waited for (tracking without it, a warning says so); one that is not an image stops the
node at start.

When no body is found, or its tip is out of the frame, nothing is published for that frame:
never a stale or made-up tip. The pipeline is tentacle_vision.tracker (no rclpy).
"""

import collections
from dataclasses import replace
import math
import os
import sys
import time

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rclpy.node import Node
from sensor_msgs.msg import Image, JointState
from tentacle_common import contract
from tentacle_common.driver_node import (declare_parameters, diagnostic_status, publisher,
                                         run_node, service, subscription)
from tentacle_common.errors import ConfigError
from tentacle_vision import image_codec
from tentacle_vision.annotate import annotate
from tentacle_vision.centreline import warm_up
from tentacle_vision.params import TRACKER_NODE, TRACKER_PARAMS
from tentacle_vision.pixels import pixel_map
from tentacle_vision.segmentation import METHODS
from tentacle_vision.tracker import Settings, status_of, Tracker

FRAME_ID = contract.WORKSPACE_FRAME
DEFAULT_BACKGROUND = '/tmp/tentacle_background.png'  # a capture goes here without a path
TIMES_KEPT = 200  # processing times behind the diagnostics' median and p95


def image_qos(reliability):
    """
    Return the frames' QoS row: the contract's (the latest two, reliable) or best effort.

    Reliable by default, because a best-effort 3 MB frame is lost more often than not between
    two processes (../shared/NOTES.md, images); a best-effort camera driver needs best_effort.
    """
    return replace(contract.FRAMES, reliable=reliability != 'best_effort')


def pose(point_m, heading_rad, header):
    """Return a PoseStamped at a workspace point (m), turned by heading_rad about z."""
    msg = PoseStamped(header=header)
    msg.pose.position.x, msg.pose.position.y = float(point_m[0]), float(point_m[1])
    msg.pose.orientation.z = math.sin(0.5 * heading_rad)
    msg.pose.orientation.w = math.cos(0.5 * heading_rad)
    return msg


class TrackerNode(Node):
    """The ROS side of the tracker."""

    def __init__(self):
        """Declare the parameters, build the tracker, wire topics."""
        super().__init__(TRACKER_NODE)
        p = declare_parameters(self, TRACKER_PARAMS)
        if p['segmentation'] not in METHODS:
            raise ConfigError(f"segmentation {p['segmentation']!r} is not one of {METHODS}")
        if p['image_reliability'] not in ('reliable', 'best_effort'):
            raise ConfigError(f"image_reliability {p['image_reliability']!r} is not reliable "
                              'or best_effort')
        h = [float(v) for v in p['homography']]
        settings = Settings(**{k: (tuple(p[k]) if isinstance(p[k], list) else p[k])
                               for k in Settings.__dataclass_fields__})
        self.background_path = p['background_image'] or DEFAULT_BACKGROUND
        try:
            waiting = p['background_image'] and not os.path.exists(p['background_image'])
            background = (image_codec.read_background(p['background_image'])
                          if p['background_image'] and not waiting else None)
            self.tracker = Tracker(p['base_px'], pixel_map(p['metres_per_px'],
                                                           h if any(h) else (), p['base_px']),
                                   settings, background)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        warm_up()  # the first frame must not wait for the compiled pass to load
        self.debug_period_s = 1.0 / p['debug_rate'] if p['debug_rate'] > 0 else math.inf
        self.debug_scale = p['debug_scale']
        self.tip_pub = publisher(self, contract.VISION_TIP)
        self.shape_pub = publisher(self, contract.VISION_SHAPE)
        self.loop_pub = publisher(self, contract.VISION_LOOP)
        self.debug_pub = publisher(self, contract.VISION_DEBUG)
        self.diag_pub = publisher(self, contract.DIAGNOSTICS)
        subscription(self, replace(contract.IMAGE, name=p['image_topic']), self.on_image,
                     image_qos(p['image_reliability']))
        self.create_timer(1.0, self.publish_diagnostics)
        service(self, contract.VISION_CAPTURE_BACKGROUND, self.on_capture_background)
        if waiting:
            self.get_logger().warning(
                f"background_image {p['background_image']} is not there yet: tracking without "
                f'one until {contract.VISION_CAPTURE_BACKGROUND.name} writes it (call it with '
                'nothing inserted)')
        self.latest_frame = None   # (encoding, decoded image): what a capture takes
        self.image_topic = p['image_topic']
        self.times = collections.deque(maxlen=TIMES_KEPT)
        self.frames = self.lost = self.loops = 0
        self.last = None          # the last Track
        self.last_problem = ''    # the last frame that could not be read
        self.next_debug = 0.0

    def on_image(self, msg):
        """Track one frame and publish what it shows."""
        t0 = time.perf_counter()
        try:
            image = image_codec.from_message(msg.encoding, msg.height, msg.width, msg.step,
                                             msg.data)
            self.latest_frame = msg.encoding, image
            track = self.tracker.track(image, msg.encoding)
        except ValueError as exc:
            self.last_problem = str(exc)
            self.get_logger().error(f'frame not tracked: {exc}', throttle_duration_sec=5.0)
            return
        header = msg.header
        header.frame_id = FRAME_ID
        if track.found:
            self.tip_pub.publish(pose(track.tip_m, track.heading_rad, header))
        elif track.loop is not None:
            loop = track.loop
            self.loop_pub.publish(JointState(
                header=header, name=['centre_x', 'centre_y', 'radius', 'turned'],
                position=[float(loop.centre_m[0]), float(loop.centre_m[1]),
                          float(loop.radius_m), float(loop.turned_rad)]))
            self.loops += 1
        else:
            self.lost += 1
        if track.centreline_m is not None:
            self.shape_pub.publish(Path(header=header, poses=[
                pose(p, 0.0, header) for p in track.centreline_m]))
        self.frames += 1
        self.times.append(time.perf_counter() - t0)
        self.last, self.last_problem = track, ''
        now = time.monotonic()
        if now >= self.next_debug:
            self.next_debug = now + self.debug_period_s
            picture = annotate(image_codec.for_tracking(msg.encoding, image), track,
                               self.debug_scale)
            height, width, step, data = image_codec.to_message(picture, 'bgr8')
            self.debug_pub.publish(Image(header=header, height=height, width=width,
                                         encoding='bgr8', step=step, data=data))

    def on_capture_background(self, _request, response):
        """Take the latest frame as the empty scene: write it, track against it."""
        if self.latest_frame is None:
            response.success, response.message = False, f'no frame yet on {self.image_topic}'
            return response
        encoding, image = self.latest_frame
        background = image_codec.for_tracking(encoding, image,
                                              colour=encoding != 'mono8')
        if not cv2.imwrite(self.background_path, background):
            response.success = False
            response.message = f'{self.background_path}: could not be written'
            return response
        self.tracker.set_background(background)
        response.success = True
        response.message = (f'background {background.shape[1]} x {background.shape[0]} px '
                            f'written to {self.background_path}, in use')
        self.get_logger().info(response.message)
        return response

    def publish_diagnostics(self):
        """Publish one status: tracking, loop or lost, and the processing time."""
        track = self.last
        if self.last_problem:
            level, message = 'error', f'frames not readable: {self.last_problem}'
        elif track is None:
            level, message = 'warn', f'no frames yet on {self.image_topic}'
        else:
            level, message = status_of(track)
        ordered = sorted(self.times)
        values = {'frames': self.frames, 'lost': self.lost, 'loops': self.loops,
                  'processing_median_ms': round(1e3 * ordered[len(ordered) // 2], 3)
                  if ordered else '',
                  'processing_p95_ms': round(1e3 * ordered[int(0.95 * (len(ordered) - 1))], 3)
                  if ordered else '',
                  'full_frame_search': track.full_frame if track else '',
                  'background': self.background_path if self.tracker.background is not None
                  else 'none'}
        msg = DiagnosticArray(status=[diagnostic_status(f'{TRACKER_NODE}: tip', self.image_topic,
                                                        level, message, values)])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)


def main(args=None):
    """Run the node until a signal."""
    run_node(sys.argv[1:] if args is None else list(args), TRACKER_NODE, TRACKER_PARAMS,
             __doc__, TrackerNode, lambda node: 'stopped')


if __name__ == '__main__':
    main()
