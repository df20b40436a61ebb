"""
tracker_node as a real process over DDS: rendered frames in, the tip and shape out.

This process publishes frames the renderer drew (their truth known) on /camera/image_raw
and checks what the node publishes against it: the tip within a pixel, the heading, the
frame's stamp echoed, nothing at all for a frame without a body, a loop for a coiled one.
"""

import sys
import threading
import time

import cv2
import numpy as np
import pytest
import rclpy  # tests/conftest.py claimed the private ROS domain before this
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rig_support import Spinner, wait_for
from sensor_msgs.msg import Image
from tentacle_common import contract
from tentacle_common.driver_node import publisher, subscription
from tentacle_sim.sim_rig import NodeProcess
from tentacle_vision import image_codec
from tentacle_vision.pixels import ScaleMap
from tentacle_vision.render import centreline_of, Renderer, to_bayer_rggb, to_bgr

pytestmark = pytest.mark.ros
BASE_PX = (120.0, 1000.0)
MAP = ScaleMap(5e-5, BASE_PX)
R = 0.015


class CameraProbe:
    """Publishes frames; records tips, shapes, loops and diagnostics."""

    def __init__(self):
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('camera_probe', context=self.context)
        self.lock = threading.Lock()
        self.got = {'tip': [], 'shape': [], 'loop': [], 'diag': []}
        self.image_pub = publisher(self.node, contract.IMAGE)
        for topic, key in ((contract.VISION_TIP, 'tip'), (contract.VISION_SHAPE, 'shape'),
                           (contract.VISION_LOOP, 'loop'), (contract.DIAGNOSTICS, 'diag')):
            subscription(self.node, topic, lambda m, k=key: self._keep(k, m))
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.spinner = Spinner(self.executor)

    def _keep(self, key, msg):
        with self.lock:
            self.got[key].append(msg)

    def publish(self, image, encoding, stamp_ns):
        height, width, step, data = image_codec.to_message(image, encoding)
        msg = Image(height=height, width=width, encoding=encoding, step=step, data=data)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10 ** 9)
        msg.header.frame_id = contract.CAMERA_FRAME
        self.image_pub.publish(msg)

    def stamped(self, key, stamp_ns):
        with self.lock:
            return [m for m in self.got[key]
                    if m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec == stamp_ns]

    def status(self):
        with self.lock:
            for array in reversed(self.got['diag']):
                for status in array.status:
                    if status.name == 'tracker_node: tip':
                        return status
        return None

    def close(self):
        self.spinner.stop()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def tracker(tmp_path):
    argv = [sys.executable, '-m', 'tentacle_vision.tracker_node', '--ros-args',
            '-p', f'base_px:=[{BASE_PX[0]}, {BASE_PX[1]}]', '-p', f'metres_per_px:={MAP.s}',
            '-p', 'debug_rate:=5.0']
    node = NodeProcess(argv, str(tmp_path / 'tracker.log'))
    probe = CameraProbe()
    try:
        assert wait_for(lambda: probe.image_pub.get_subscription_count() > 0, 20.0), \
            node.output()
        yield probe, node
    finally:
        probe.close()
        code = node.stop()
        assert code == 0, node.output()


def send_until_answered(probe, image, encoding, key, stamp_ns, timeout_s=20.0):
    """Publish a frame (again, while discovery or the first compile runs) until answered."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        probe.publish(image, encoding, stamp_ns)
        if wait_for(lambda: probe.stamped(key, stamp_ns), 1.0):
            return probe.stamped(key, stamp_ns)[0]
    return None


@pytest.mark.parametrize('encoding', ['mono8', 'bayer_rggb8'])
def test_the_tip_and_shape_of_a_frame_carry_its_stamp_and_its_truth(tracker, encoding):
    probe, node = tracker
    renderer = Renderer(MAP, noise_sigma=3.0)
    truth = renderer.render(centreline_of([(0.02, 0.0), (np.pi / 2 * R, 1 / R)]), 1e-3)
    frame = truth.image if encoding == 'mono8' else to_bayer_rggb(to_bgr(truth.image))
    tip = send_until_answered(probe, frame, encoding, 'tip', 1_000_000_123)
    assert tip is not None, node.output()
    assert tip.header.frame_id == contract.WORKSPACE_FRAME
    measured = np.array([tip.pose.position.x, tip.pose.position.y])
    assert np.hypot(*(measured - truth.tip_m)) <= 1.0 * MAP.s
    heading = 2 * np.arctan2(tip.pose.orientation.z, tip.pose.orientation.w)
    assert abs(np.degrees(heading - truth.heading_rad)) <= 2.0
    assert wait_for(lambda: probe.stamped('shape', 1_000_000_123), 2.0)
    shape = probe.stamped('shape', 1_000_000_123)[0]
    first, last = shape.poses[0].pose.position, shape.poses[-1].pose.position
    assert np.hypot(first.x, first.y) <= 3 * MAP.s                      # from the base
    assert (last.x, last.y) == (tip.pose.position.x, tip.pose.position.y)  # to the tip
    assert wait_for(lambda: probe.status() is not None
                    and probe.status().message == 'tracking', 5.0)


def test_a_frame_without_a_body_publishes_nothing_and_says_lost(tracker):
    probe, node = tracker
    renderer = Renderer(MAP, noise_sigma=3.0)
    body = renderer.render(centreline_of([(0.03, 0.0)]), 1e-3)
    assert send_until_answered(probe, body.image, 'mono8', 'tip', 2_000_000_000) is not None
    t0 = time.monotonic()
    for k in range(5):
        probe.publish(renderer.background, 'mono8', 3_000_000_000 + k)
        time.sleep(0.05)
    assert wait_for(lambda: probe.status() is not None
                    and probe.status().message.startswith('lost: no body'), 5.0)
    assert time.monotonic() - t0 < 5.0
    for k in range(5):
        assert not probe.stamped('tip', 3_000_000_000 + k)     # no stale or made-up tip
        assert not probe.stamped('shape', 3_000_000_000 + k)


def test_a_coiled_body_is_a_loop_not_a_tip(tracker):
    probe, node = tracker
    line = centreline_of([(0.02, 0.0), (np.radians(380) * R, 1 / R)])
    truth = Renderer(MAP, noise_sigma=3.0).render(line, 1e-3)
    loop = send_until_answered(probe, truth.image, 'mono8', 'loop', 4_000_000_000)
    assert loop is not None, node.output()
    values = dict(zip(loop.name, loop.position))
    assert values['centre_x'] == pytest.approx(0.02, abs=2 * MAP.s)
    assert values['centre_y'] == pytest.approx(R, abs=2 * MAP.s)
    assert values['radius'] == pytest.approx(R, abs=3 * MAP.s)
    assert values['turned'] >= np.radians(330)
    assert not probe.stamped('tip', 4_000_000_000)


def test_camera_node_replays_a_recorded_run_into_the_tracker(tmp_path):
    """camera_node (a folder of frames) -> tracker_node -> tips that follow the truth."""
    renderer = Renderer(MAP, noise_sigma=3.0)
    truths = []
    for k in range(6):   # the body grows 2 mm a frame, then bends
        line = centreline_of([(0.02 + 0.002 * k, 0.0), (0.004 * k, 20.0)])
        truths.append(renderer.render(line, 1e-3))
        cv2.imwrite(str(tmp_path / f'frame_{k:03d}.png'), truths[-1].image)
    tracker = NodeProcess([sys.executable, '-m', 'tentacle_vision.tracker_node', '--ros-args',
                           '-p', f'base_px:=[{BASE_PX[0]}, {BASE_PX[1]}]',
                           '-p', f'metres_per_px:={MAP.s}'], str(tmp_path / 'tracker.log'))
    probe = CameraProbe()
    camera = None
    try:
        # The probe must hear the tracker before the run starts: tips are not kept for it.
        assert wait_for(lambda: probe.node.count_publishers(contract.VISION_TIP.name) > 0, 20.0)
        time.sleep(0.5)
        camera = NodeProcess([sys.executable, '-m', 'tentacle_vision.camera_node', '--ros-args',
                              '-p', f'source:={tmp_path}', '-p', 'rate:=5.0',
                              '-p', 'encoding:=mono8', '-p', 'wait_for_subscriber:=true'],
                             str(tmp_path / 'camera.log'))
        assert wait_for(lambda: len(probe.got['tip']) >= 6, 30.0), (
            len(probe.got['tip']), camera.output(), tracker.output())
        tips = [np.array([m.pose.position.x, m.pose.position.y]) for m in probe.got['tip']]
        errors_m = [min(np.hypot(*(tip - t.tip_m)) for t in truths) for tip in tips]
        assert max(errors_m) <= 1.0 * MAP.s                      # each tip is a true one
        order = [int(np.argmin([np.hypot(*(tip - t.tip_m)) for t in truths])) for tip in tips]
        assert order == list(range(6))                           # in the order recorded
        assert wait_for(lambda: 'source ended after 6 frames' in camera.output(), 5.0)
    finally:
        probe.close()
        codes = [node.stop() for node in (camera, tracker) if node is not None]
    assert codes == [0, 0], (camera.output(), tracker.output())
