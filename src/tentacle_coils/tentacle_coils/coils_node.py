"""
coils_node: field commands in, three supplies driven, measured currents and field out.

Topics and services (DESIGN.md): /coils/field_cmd (in), /coils/currents, /coils/field,
/diagnostics (out), /coils/enable (service), /estop (in, transient local). The logic lives in
field_map.py (maths and limits) and coil_bank.py (supplies, slew, watchdog, safe stop); this
module only wires it to ROS.
"""

import logging
import math
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from rclpy.time import Time

from tentacle_coils.bank_process import BankClient
from tentacle_coils.errors import CommandRejected
from tentacle_coils.field_map import ActuationMap, Limits, plan_currents
from tentacle_coils.params import COILS_PARAMS, NODE_NAME
from tentacle_common import contract
from tentacle_common.driver_node import (declare_parameters, diagnostic_status, publisher,
                                         RosLogHandler, run_node, service, subscription)

FRAME_ID = contract.COILS_FRAME


class CoilsNode(Node):
    """Wire the coil bank to the topic contract."""

    def __init__(self):
        """Declare parameters, build the bank and start talking to the supplies."""
        super().__init__(NODE_NAME)
        p = declare_parameters(self, COILS_PARAMS)
        self.actuation = ActuationMap(p['actuation_matrix'], p['field_offset'])
        self.limits = Limits(p['max_current'], p['max_field'], p['clamp'])
        self.auto_enable = p['auto_enable']
        self._log_handler = RosLogHandler(self.get_logger())
        logging.getLogger('tentacle_coils').addHandler(self._log_handler)
        logging.getLogger('tentacle_coils').setLevel(logging.INFO)
        self.rejected = 0
        self.last_rejection = ''
        self._last_logged = {}
        # The bank runs in its own process (bank_process.py): serial timing never waits for
        # this executor, and the coils go to zero if this process dies.
        self.bank = BankClient(
            on_rejected=self._reject,
            ports=list(p['ports']), dialect=p['dialect'], baud=p['baud'],
            addresses=list(p['addresses']), polarity_inverted=list(p['polarity_inverted']),
            polarity_mode=p['polarity_mode'], max_current_a=p['max_current'],
            slew_rate_a_per_s=p['slew_rate'], watchdog_s=p['watchdog_s'],
            readback_period_s=1.0 / p['publish_rate'], retries=p['retries'],
            reply_timeout_s=p['reply_timeout_s'], max_turnaround_s=p['max_turnaround_s'],
            voltage_limit_v=p['voltage_limit'])

        self.currents_pub = publisher(self, contract.CURRENTS)
        self.field_pub = publisher(self, contract.FIELD)
        self.diag_pub = publisher(self, contract.DIAGNOSTICS)
        subscription(self, contract.FIELD_CMD, self.on_field_cmd)
        subscription(self, contract.ESTOP, self.on_estop)
        service(self, contract.COILS_ENABLE, self.on_enable)
        self.create_timer(1.0 / p['publish_rate'], self.publish_state)
        self.create_timer(1.0, self.publish_diagnostics)
        if self.auto_enable:
            self._auto_enable_timer = self.create_timer(0.05, self._try_auto_enable)
        self.get_logger().info(
            f"coils_node: {p['dialect']} at {p['baud']} baud on {list(p['ports'])}; "
            f"max {p['max_current']:g} A, {p['max_field'] * 1e3:g} mT, "
            f"slew {p['slew_rate']:g} A/s, watchdog {p['watchdog_s']:g} s")

    def _try_auto_enable(self):
        if self.bank.deaths:  # after a bank process died only the operator enables
            self._auto_enable_timer.cancel()
            return
        if self.bank.connected() and not self.bank.estopped:
            ok, message = self.bank.enable(True)
            if ok:
                self.get_logger().info(f'auto_enable: {message}')
                self._auto_enable_timer.cancel()

    def _reject(self, reason):
        """Count a rejected command and log its reason (once a second per distinct reason)."""
        self.rejected += 1
        self.last_rejection = reason
        now = time.monotonic()
        if now - self._last_logged.get(reason, -math.inf) >= 1.0:
            if len(self._last_logged) > 64:  # reasons carry values: forget the stale ones
                self._last_logged = {r: t for r, t in self._last_logged.items()
                                     if now - t < 1.0}
            self._last_logged[reason] = now
            self.get_logger().warning(f'field command rejected: {reason}')

    def on_field_cmd(self, msg):
        """Validate a field command and hand its currents to the bank."""
        if msg.header.frame_id != FRAME_ID:
            self._reject(f"frame_id '{msg.header.frame_id}' is not '{FRAME_ID}'")
            return
        try:
            currents, note = plan_currents((msg.vector.x, msg.vector.y, msg.vector.z),
                                           self.actuation, self.limits)
            self.bank.command(currents)
        except CommandRejected as exc:
            self._reject(str(exc))
            return
        if note:
            self.get_logger().warning(f'field command clamped: {note}',
                                      throttle_duration_sec=1.0)

    def on_estop(self, msg):
        """Engage or release the emergency stop."""
        if msg.data != self.bank.estopped:
            self.get_logger().warning('estop ' + ('ENGAGED: ramping to zero, outputs off'
                                                  if msg.data else 'released'))
        try:
            self.bank.set_estop(msg.data)
        except CommandRejected as exc:
            self.get_logger().error(f'estop could not reach the coil bank: {exc}')

    def on_enable(self, request, response):
        """Energise or de-energise the outputs."""
        response.success, response.message = self.bank.enable(request.data)
        if self.auto_enable:
            self._auto_enable_timer.cancel()  # the operator decides from now on
        return response

    @staticmethod
    def _stamped(vector, stamp_s):
        msg = Vector3Stamped()
        msg.header.stamp = Time(nanoseconds=round(stamp_s * 1e9)).to_msg()
        msg.header.frame_id = FRAME_ID
        msg.vector.x, msg.vector.y, msg.vector.z = (float(v) for v in vector)
        return msg

    def publish_state(self):
        """
        Publish measured currents and the field they make (nothing while any is unknown).

        Stamped with the time the oldest of the three readings was asked for (wall clock, as
        ROS time), not the time of publishing: a subscriber knows how old the field is.
        """
        measured, at_s = self.bank.measured_currents(), self.bank.measured_at()
        if not all(math.isfinite(v) for v in [*measured, at_s]):
            return
        self.currents_pub.publish(self._stamped(measured, at_s))
        self.field_pub.publish(self._stamped(self.actuation.field(measured), at_s))

    def publish_diagnostics(self):
        """Publish one status per supply and one for the bank."""
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        level, message = self.bank.status()
        array.status.append(diagnostic_status(
            'coils: bank', 'coils', level, message,
            {'commands_rejected': self.rejected, 'last_rejection': self.last_rejection,
             'bank_pid': self.bank.popen.pid, 'bank_deaths': len(self.bank.deaths),
             'spare_pid': self.bank.spare_pid or 'none',
             'spare_deaths': len(self.bank.spare_deaths)}))
        for snap in self.bank.snapshots():
            if not snap['connected']:
                level, message = 'error', f"disconnected: {snap['last_error']}"
            elif snap['last_error']:
                level, message = 'warn', f"last error: {snap['last_error']}"
            else:
                level, message = 'ok', 'connected'
            array.status.append(diagnostic_status(
                f"coils: supply {snap['axis']}", f"{snap['port']}@{snap['address']}", level,
                message, snap))
        self.diag_pub.publish(array)

    def shutdown(self):
        """Ramp to zero and switch every output off; return what was not read back so."""
        # The ROS context may be gone already (signal): log the ramp-down to stderr.
        logger = logging.getLogger('tentacle_coils')
        logger.removeHandler(self._log_handler)
        fallback = logging.StreamHandler(sys.stderr)
        logger.addHandler(fallback)
        try:
            self.bank.shutdown('node exit')
            return self.bank.unsafe
        finally:
            logger.removeHandler(fallback)


def main(args=None):
    """Run the node; on exit (Ctrl-C, SIGTERM, error) leave the coils at zero and off."""
    def stop_safely(node):
        unsafe = node.shutdown()
        return 'outputs ' + ('zero and off' if not unsafe else 'NOT confirmed zero and off: '
                             + '; '.join(unsafe) + ': check the supplies')
    run_node(sys.argv[1:] if args is None else list(args), NODE_NAME, COILS_PARAMS, __doc__,
             CoilsNode, stop_safely)


if __name__ == '__main__':
    main()
