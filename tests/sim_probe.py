"""A ROS node for tests of the simulated rig: commands it as a lab would, records its truth."""

import threading
import time

from geometry_msgs.msg import Vector3Stamped
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rig_support import Spinner
from std_msgs.msg import Bool, Float64
from std_srvs.srv import SetBool, Trigger
from tentacle_common import contract
from tentacle_common.driver_node import client, publisher, subscription
from tentacle_common.waiting import wait_for

TOPICS = {'shape': contract.SIM_SHAPE, 'tip': contract.VISION_TIP,
          'contact': contract.SIM_CONTACT, 'diagnostics': contract.DIAGNOSTICS,
          'field': contract.FIELD, 'inserter': contract.axis_state('inserter'),
          'markers': contract.SIM_MARKERS}


def stamp_s(msg):
    """Return a message's header stamp, s."""
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def points_of(path_msg):
    """Return (N, 3) the positions of a nav_msgs/Path, m."""
    return np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                     for p in path_msg.poses])


class SimProbe:
    """Own a private context, one node and an executor thread."""

    def __init__(self):
        """Create publishers, subscriptions and clients."""
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('sim_probe', context=self.context)
        self.lock = threading.Lock()
        self.got = {key: [] for key in TOPICS}
        for key, topic in TOPICS.items():
            subscription(self.node, topic, lambda m, k=key: self._keep(k, m))
        self.field_pub = publisher(self.node, contract.FIELD_CMD)
        self.estop_pub = publisher(self.node, contract.ESTOP)
        self.target_pub = publisher(self.node, contract.axis_target('inserter'))
        self.home_client = client(self.node, contract.axis_service('inserter', 'home'))
        self.enable_client = client(self.node, contract.COILS_ENABLE)
        self.background_client = client(self.node, contract.VISION_CAPTURE_BACKGROUND)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.spinner = Spinner(self.executor)
        # A held field is re-sent at 5 Hz, as a player does: coils_node's watchdog ramps to
        # zero after 1 s without a command.
        self._held, self._stop = None, threading.Event()
        self._holder = threading.Thread(target=self._hold, daemon=True)
        self._holder.start()

    def _hold(self):
        while not self._stop.wait(0.2):
            held = self._held
            if held is not None:
                self.command_field(held)

    def hold_field(self, field_t):
        """Command a field (T) now and every 0.2 s from now on; None: stop commanding."""
        self._held = None if field_t is None else [float(v) for v in field_t]
        if field_t is not None:
            self.command_field(field_t)

    def _keep(self, key, msg):
        with self.lock:
            self.got[key].append((time.monotonic(), msg))
            del self.got[key][:-400]   # the recent past is all a test looks at

    def latest(self, key, since=0.0):
        """Return the newest message of a kind received after a monotonic time, or None."""
        with self.lock:
            fresh = [m for t, m in self.got[key] if t >= since]
        return fresh[-1] if fresh else None

    def every(self, key, since=0.0):
        """Return every kept message of a kind received after a monotonic time."""
        with self.lock:
            return [m for t, m in self.got[key] if t >= since]

    def shape(self, since=0.0):
        """Return the newest /sim/shape points (N, 3) received after a time, or None."""
        msg = self.latest('shape', since)
        return None if msg is None else points_of(msg)

    def command_field(self, field_t):
        """Publish one field command (T, frame coils)."""
        msg = Vector3Stamped()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.header.frame_id = contract.COILS_FRAME
        msg.vector.x, msg.vector.y, msg.vector.z = (float(v) for v in field_t)
        self.field_pub.publish(msg)

    def estop(self, active):
        """Publish the emergency stop state."""
        self.estop_pub.publish(Bool(data=active))

    def target(self, position_m):
        """Publish an inserter target, m."""
        self.target_pub.publish(Float64(data=float(position_m)))

    def call(self, which, request, timeout_s=20.0):
        """Call 'home', 'enable' or 'background'; return the response, None on timeout."""
        handle = {'home': self.home_client, 'enable': self.enable_client,
                  'background': self.background_client}[which]
        if not handle.wait_for_service(timeout_sec=timeout_s):
            return None
        future = handle.call_async(request)
        wait_for(future.done, timeout_s)
        return future.result() if future.done() else None

    def home(self):
        """Home the inserter; return whether it said so."""
        response = self.call('home', Trigger.Request())
        return response is not None and response.success

    def capture_background(self):
        """Have the tracker take its next frame as the empty scene; return whether it did."""
        response = self.call('background', Trigger.Request())
        return response is not None and response.success

    def enable_coils(self, on=True):
        """Call /coils/enable; return whether it succeeded."""
        response = self.call('enable', SetBool.Request(data=on))
        return response is not None and response.success

    def status(self, name, since=0.0):
        """Return (level, message, values) of the newest diagnostic status named so, or None."""
        for array in reversed(self.every('diagnostics', since)):
            for status in array.status:
                if status.name == name:
                    return status.level, status.message, {v.key: v.value for v in status.values}
        return None

    def close(self):
        """Stop commanding, stop spinning and shut the context down."""
        self._stop.set()
        self._holder.join(timeout=2.0)
        self.spinner.stop()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def arc_length_m(points):
    """Return the length of a polyline (N, 3), m."""
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))) if len(points) > 1 \
        else 0.0
