"""
inserter_node as a real process over DDS, driving the gcode stage emulator over a pty.

The emulator runs in this process (its pty path is what the node opens); what the node
publishes is checked against the emulator's true position.
"""

import math
import sys
import threading
import time

import pytest
import rclpy  # tests/conftest.py claimed the private ROS domain before this
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rig_support import wait_for
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64
from std_srvs.srv import Trigger
from tentacle_sim.sim_rig import NodeProcess
from tentacle_sim.stage_emulator import GcodeStage

pytestmark = pytest.mark.ros
STEP_M = 1e-5  # 100 steps a mm


class AxisProbe:
    """Publishes targets and the estop, calls stop and home, records /inserter/state."""

    def __init__(self):
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('axis_probe', context=self.context)
        self.states, self.lock = [], threading.Lock()
        self.target_pub = self.node.create_publisher(Float64, '/inserter/target', 10)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.estop_pub = self.node.create_publisher(Bool, '/estop', latched)
        self.node.create_subscription(JointState, '/inserter/state', self._keep, 10)
        self.clients = {name: self.node.create_client(Trigger, f'/inserter/{name}')
                        for name in ('stop', 'home')}
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()

    def _keep(self, msg):
        with self.lock:
            self.states.append((time.monotonic(), msg))

    def position(self, since=0.0):
        with self.lock:
            fresh = [m for t, m in self.states if t >= since]
        return fresh[-1].position[0] if fresh else None

    def call(self, name, timeout_s=10.0):
        client = self.clients[name]
        if not client.wait_for_service(timeout_sec=timeout_s):
            return None
        future = client.call_async(Trigger.Request())
        wait_for(future.done, timeout_s)
        return future.result()

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def axis(tmp_path):
    link = str(tmp_path / 'stage')
    emu = GcodeStage('e', link_path=link, accel_m_s2=0.5).start()
    node = NodeProcess([sys.executable, '-m', 'tentacle_inserter.inserter_node', '--ros-args',
                        '-p', f'port:={link}', '-p', 'max_length:=0.05',
                        '-p', 'max_speed:=0.01', '-p', 'acceleration:=0.5',
                        '-p', 'reply_timeout_s:=0.2'], str(tmp_path / 'node.log'))
    probe = AxisProbe()
    try:
        response = probe.call('home', 20.0)
        assert response is not None and response.success, node.output()
        yield probe, emu, node
    finally:
        probe.close()
        code = node.stop()
        emu.stop()
        assert code == 0, node.output()


def test_a_target_moves_the_axis_and_state_follows_the_truth(axis):
    probe, emu, node = axis
    probe.target_pub.publish(Float64(data=0.008))
    assert wait_for(lambda: emu.state()['position_m'] == pytest.approx(0.008, abs=STEP_M), 10)
    since = time.monotonic() + 0.2
    assert wait_for(lambda: probe.position(since) is not None, 2.0)
    assert abs(probe.position(since) - emu.state()['position_m']) <= STEP_M


@pytest.mark.parametrize('bad', [math.nan, math.inf, -0.001, 0.06])
def test_a_bad_target_is_refused_and_never_reaches_the_wire(axis, bad):
    probe, emu, node = axis
    probe.target_pub.publish(Float64(data=bad))
    assert wait_for(lambda: 'target refused' in node.output(), 5.0)
    time.sleep(0.3)
    assert not [e for e in emu.log if e.get('command') == 'G1']


def test_stop_and_estop_halt_and_hold(axis):
    probe, emu, node = axis
    probe.target_pub.publish(Float64(data=0.04))
    assert wait_for(lambda: emu.state()['moving'], 5.0)
    assert probe.call('stop').success
    assert wait_for(lambda: not emu.state()['moving'], 1.0)
    assert probe.call('home').success
    probe.estop_pub.publish(Bool(data=True))
    time.sleep(0.3)
    moves = len([e for e in emu.log if e.get('command') == 'G1'])
    probe.target_pub.publish(Float64(data=0.01))
    time.sleep(0.5)
    assert len([e for e in emu.log if e.get('command') == 'G1']) == moves
    assert not emu.state()['moving']
    probe.estop_pub.publish(Bool(data=False))
