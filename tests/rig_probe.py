"""A ROS node for tests: publishes commands to the rig and records what it publishes."""

import threading
import time

from geometry_msgs.msg import Vector3Stamped
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rig_support import Spinner
from std_msgs.msg import Bool
from std_srvs.srv import SetBool
from tentacle_common import contract
from tentacle_common.driver_node import client, publisher, subscription


class RigProbe:
    """Own a private context, one node and an executor thread."""

    def __init__(self):
        """Create publishers, subscriptions and the enable client."""
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('rig_probe', context=self.context)
        self.lock = threading.Lock()
        self.currents = []
        self.fields = []
        self.diagnostics = []
        self.field_pub = publisher(self.node, contract.FIELD_CMD)
        self.estop_pub = publisher(self.node, contract.ESTOP)
        subscription(self.node, contract.CURRENTS, lambda m: self._keep(self.currents, m))
        subscription(self.node, contract.FIELD, lambda m: self._keep(self.fields, m))
        subscription(self.node, contract.DIAGNOSTICS,
                     lambda m: self._keep(self.diagnostics, m))
        self.enable_client = client(self.node, contract.COILS_ENABLE)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.spinner = Spinner(self.executor)

    def _keep(self, store, msg):
        with self.lock:
            store.append((time.monotonic(), msg))

    def command_field(self, field_t, frame_id=contract.COILS_FRAME):
        """Publish one field command (T)."""
        msg = Vector3Stamped()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.header.frame_id = frame_id
        msg.vector.x, msg.vector.y, msg.vector.z = (float(v) for v in field_t)
        self.field_pub.publish(msg)

    def estop(self, active):
        """Publish the emergency stop state."""
        self.estop_pub.publish(Bool(data=active))

    def enable(self, on, timeout_s=5.0):
        """Call /coils/enable; return the response (None on timeout)."""
        if not self.enable_client.wait_for_service(timeout_sec=timeout_s):
            return None
        future = self.enable_client.call_async(SetBool.Request(data=on))
        deadline = time.monotonic() + timeout_s
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        return future.result() if future.done() else None

    def wait_for_subscriber(self, timeout_s=10.0):
        """Wait until the node subscribes to /coils/field_cmd; return True if it did."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.field_pub.get_subscription_count() > 0:
                return True
            time.sleep(0.02)
        return False

    def latest(self, store, since=0.0):
        """Return the newest message received after a time, or None."""
        with self.lock:
            fresh = [m for t, m in store if t >= since]
        return fresh[-1] if fresh else None

    def supply_status(self, axis, since=0.0):
        """Return the latest DiagnosticStatus of one supply received after a time, or None."""
        array = self.latest(self.diagnostics, since)
        if array is None:
            return None
        for status in array.status:
            if status.name == f'coils: supply {axis}':
                return status
        return None

    def close(self):
        """Stop the executor and shut the context down."""
        self.spinner.stop()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
