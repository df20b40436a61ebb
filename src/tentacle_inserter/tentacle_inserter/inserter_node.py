"""
inserter_node: one linear axis (the inserter, or the backbone stage) on a serial line.

Topics under the axis namespace (parameter ``axis``, DESIGN.md): /<axis>/target
(std_msgs/Float64, absolute position, m), /<axis>/state (sensor_msgs/JointState: position m,
velocity m/s, at ``state_rate``), /<axis>/stop and /<axis>/home (std_srvs/Trigger),
/<axis>/enable (std_srvs/SetBool: false stops, switches the motor off and refuses targets),
/estop (std_msgs/Bool, transient local) honoured, /diagnostics. A target that is not finite or is
outside [0, max_length] is refused with a logged reason and never reaches the wire; the
axis moves to the latest target only, a move that does not end in its expected time stops
the axis, and after a stop or a lost line it must be homed again (home: "zero is here"); a
target that arrives while the line is down is refused, never kept for the reconnect. An
``axis`` that is not one ROS name token is refused at start (exit 2), and so is an axis other
than ``inserter`` under the default node name: the backbone runs as
``-r __node:=backbone_node`` (its params file section named so), so two axes never share a
node name.
A step1mm axis reports a counted position: /diagnostics says it is estimated. The axis logic
is tentacle_inserter.axis_worker and stage (no rclpy), run in a process of its own
(axis_process) so that the axis stops however this node dies; this module is the ROS glue.
"""

import logging
import sys

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState
from tentacle_common import contract
from tentacle_common.driver_node import (declare_parameters, diagnostic_status, publisher,
                                         RosLogHandler, run_node, service, subscription)
from tentacle_common.errors import ConfigError
from tentacle_inserter.axis_process import AxisClient, LOGGER
from tentacle_inserter.params import check_axis, INSERTER_PARAMS, NODE_NAME
from tentacle_inserter.stage import TargetRefused


class InserterNode(Node):
    """The ROS side of one axis."""

    def __init__(self):
        """Declare the parameters, start the axis process, wire topics and services."""
        super().__init__(NODE_NAME)
        p = declare_parameters(self, INSERTER_PARAMS)
        self.axis = check_axis(p['axis'])  # before the axis process: nothing is started
        if self.axis != 'inserter' and self.get_name() == NODE_NAME:
            # Two axes under one node name would share its parameters and its log.
            raise ConfigError(f'axis {self.axis} runs under its own node name, not {NODE_NAME}:'
                              f' add -r __node:={contract.axis_node_name(self.axis)} after '
                              '--ros-args (its params file section takes that name too)')
        logger = logging.getLogger(LOGGER)
        logger.addHandler(RosLogHandler(self.get_logger()))
        logger.setLevel(logging.INFO)
        # The axis runs in its own process (axis_process.py): it stops the axis if this
        # process dies, however it dies.
        self.client = AxisClient({**p, 'axis': self.axis}, on_refused=self._refused)
        self.port, self.dialect = p['port'], p['dialect']
        self.state_pub = publisher(self, contract.axis_state(self.axis))
        self.diag_pub = publisher(self, contract.DIAGNOSTICS)
        subscription(self, contract.axis_target(self.axis), self.on_target)
        subscription(self, contract.ESTOP, self.on_estop)
        service(self, contract.axis_service(self.axis, 'stop'), self.on_stop)
        service(self, contract.axis_service(self.axis, 'home'), self.on_home)
        service(self, contract.axis_service(self.axis, 'enable'), self.on_enable)
        self.create_timer(1.0 / p['state_rate'], self.publish_state)
        self.create_timer(1.0, self.publish_diagnostics)

    def on_target(self, msg):
        """Hand a target to the axis, or log why it is refused."""
        try:
            self.client.set_target(msg.data)
        except TargetRefused as exc:
            self._refused(str(exc))

    def _refused(self, reason):
        self.get_logger().warning(f'{self.axis}: target refused: {reason}')

    def on_estop(self, msg):
        """Engage or release the estop."""
        self.client.set_estop(msg.data)
        if msg.data:
            self.get_logger().warning(f'{self.axis}: estop: axis stopped, targets refused')

    def on_stop(self, _request, response):
        """Stop now."""
        self.client.stop()
        response.success, response.message = True, 'stopping: home again before moving'
        return response

    def on_enable(self, request, response):
        """Enable (targets taken) or disable (stop, motor off, targets refused)."""
        self.client.set_enabled(request.data)
        response.success = True
        response.message = 'enabled' if request.data else 'stopping, motor off, targets refused'
        return response

    def on_home(self, _request, response):
        """Make where the axis stands its zero."""
        response.success, response.message = self.client.home()
        return response

    def publish_state(self):
        """Publish position and velocity (nothing while the position is unknown)."""
        snap = self.client.snapshot()
        if snap['position_m'] is None:
            return
        msg = JointState(name=[self.axis], position=[float(snap['position_m'])],
                         velocity=[float(snap['velocity_m_s'])])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.state_pub.publish(msg)

    def publish_diagnostics(self):
        """Publish one status for the axis."""
        snap = self.client.snapshot()
        level, message = self.client.status()
        values = {**snap, 'position': 'measured' if snap['measured']
                  else 'estimated (counted, no readback)', 'dialect': self.dialect}
        msg = DiagnosticArray(status=[diagnostic_status(f'{NODE_NAME}: {self.axis}', self.port,
                                                        level, message, values)])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)

    def shutdown(self):
        """Stop the axis and close the line; return whether the stop was answered."""
        return self.client.shutdown()


def main(args=None):
    """Run the node; on exit (Ctrl-C, SIGTERM, error) leave the axis stopped."""
    def stop_safely(node):
        return 'axis stopped' if node.shutdown() else \
            'stop NOT confirmed by the stage: check the axis'
    run_node(sys.argv[1:] if args is None else list(args), NODE_NAME, INSERTER_PARAMS,
             __doc__, InserterNode, stop_safely)


if __name__ == '__main__':
    main()
