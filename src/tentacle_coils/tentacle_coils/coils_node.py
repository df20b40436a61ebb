"""
coils_node: field commands in, three supplies driven, measured currents and field out.

Topics and services (DESIGN.md): /coils/field_cmd (in), /coils/currents, /coils/field,
/diagnostics (out), /coils/enable (service), /estop (in, transient local). The logic lives in
field_map.py (maths and limits) and coil_bank.py (supplies, slew, watchdog, safe stop); this
module only wires it to ROS.
"""

import logging
import math
import os
import signal
import sys
import tempfile
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Bool
from std_srvs.srv import SetBool

from tentacle_coils.bank_process import BankClient
from tentacle_coils.errors import CoilsError, CommandRejected, ConfigError
from tentacle_coils.field_map import ActuationMap, Limits, plan_currents
from tentacle_coils.params import check_ros_args, COILS_PARAMS, describe
import yaml

FRAME_ID = 'coils'
LEVELS = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN,
          'error': DiagnosticStatus.ERROR}


def declare_parameters(node, table):
    """Declare every row of a parameter table with a descriptor; return {name: value}."""
    values = {}
    for p in table:
        descriptor = ParameterDescriptor(description=p.description, read_only=True)
        if p.low is not None and isinstance(p.default, float):
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(p.low), to_value=float(p.high), step=0.0)]
        elif p.low is not None and isinstance(p.default, int):
            descriptor.integer_range = [IntegerRange(
                from_value=int(p.low), to_value=int(p.high), step=1)]
        values[p.name] = node.declare_parameter(p.name, p.default, descriptor).value
    return values


class RosLogHandler(logging.Handler):
    """Forward the pure code's Python logging to the node's ROS logger."""

    def __init__(self, ros_logger):
        """Wrap a ROS logger."""
        super().__init__()
        self.ros_logger = ros_logger

    def emit(self, record):
        """Log one record at the matching ROS severity."""
        if record.levelno >= logging.ERROR:
            self.ros_logger.error(self.format(record))
        elif record.levelno >= logging.WARNING:
            self.ros_logger.warning(self.format(record))
        else:
            self.ros_logger.info(self.format(record))


class CoilsNode(Node):
    """Wire the coil bank to the topic contract."""

    def __init__(self):
        """Declare parameters, build the bank and start talking to the supplies."""
        super().__init__('coils_node')
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

        self.currents_pub = self.create_publisher(Vector3Stamped, '/coils/currents', 10)
        self.field_pub = self.create_publisher(Vector3Stamped, '/coils/field', 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(Vector3Stamped, '/coils/field_cmd', self.on_field_cmd, 10)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(Bool, '/estop', self.on_estop, latched)
        self.create_service(SetBool, '/coils/enable', self.on_enable)
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

    def _stamped(self, vector):
        msg = Vector3Stamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = FRAME_ID
        msg.vector.x, msg.vector.y, msg.vector.z = (float(v) for v in vector)
        return msg

    def publish_state(self):
        """Publish measured currents and the field they make (nothing while any is unknown)."""
        measured = self.bank.measured_currents()
        if not all(math.isfinite(v) for v in measured):
            return
        self.currents_pub.publish(self._stamped(measured))
        self.field_pub.publish(self._stamped(self.actuation.field(measured)))

    def publish_diagnostics(self):
        """Publish one status per supply and one for the bank."""
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        level, message = self.bank.status()
        bank = DiagnosticStatus(name='coils: bank', hardware_id='coils',
                                level=LEVELS[level], message=message)
        bank.values = [KeyValue(key='commands_rejected', value=str(self.rejected)),
                       KeyValue(key='last_rejection', value=self.last_rejection),
                       KeyValue(key='bank_pid', value=str(self.bank.popen.pid)),
                       KeyValue(key='bank_deaths', value=str(len(self.bank.deaths)))]
        array.status.append(bank)
        for snap in self.bank.snapshots():
            if not snap['connected']:
                level, message = 'error', f"disconnected: {snap['last_error']}"
            elif snap['last_error']:
                level, message = 'warn', f"last error: {snap['last_error']}"
            else:
                level, message = 'ok', 'connected'
            status = DiagnosticStatus(
                name=f"coils: supply {snap['axis']}",
                hardware_id=f"{snap['port']}@{snap['address']}", level=LEVELS[level],
                message=message)
            status.values = [KeyValue(key=k, value=str(v)) for k, v in snap.items()]
            array.status.append(status)
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


def _already_stopping(_signum, _frame):
    """Say that a signal changes nothing now: the safe stop runs to its end."""
    # os.write: a print here could re-enter the stderr buffer the main thread is writing to.
    os.write(2, b'coils_node: already stopping safely (ramp to zero, outputs off): '
                b'signal ignored\n')


def spin_until_signal(node, poll_s=0.1):
    """
    Spin until SIGINT or SIGTERM (or the context ends); return the signal number or 0.

    rclpy's own handlers shut the context down and then raise KeyboardInterrupt at whatever
    bytecode is running; if that is a destructor the exception is swallowed and the next
    wait fails on the dead context. Here a signal only sets a flag, so the executor stops
    between callbacks and the context stays valid for the safe stop that follows. From the
    first signal on, further ones only print a note (there is no moment in between when a
    second signal could end the process mid-stop).
    """
    stop = threading.Event()
    received = []

    def on_signal(signum, _frame):
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, _already_stopping)
        received.append(signum)
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while not stop.is_set() and node.context.ok():
            executor.spin_once(timeout_sec=poll_s)
    finally:
        executor.remove_node(node)
        executor.shutdown()
        if not received:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    return received[0] if received else 0


def _prepare_args(argv):
    """
    Check --ros-args against the parameter table before rcl reads them.

    :return: (argv for rclpy, warnings, temporary files to remove after rclpy.init)
    :raises ConfigError: a params file that is missing, unreadable or has a wrong type
    """
    checked, warnings, rewrite = check_ros_args(argv)
    temporary = []
    for index, document in rewrite.items():
        handle = tempfile.NamedTemporaryFile('w', prefix='coils_node_params_', suffix='.yaml',
                                             delete=False)
        with handle:
            yaml.safe_dump(document, handle)
        temporary.append(handle.name)
        checked[index] = handle.name
    return checked, warnings, temporary


def main(args=None):
    """Run the node; on exit (Ctrl-C, SIGTERM, error) leave the coils at zero and off."""
    argv = sys.argv[1:] if args is None else list(args)
    if '--help' in argv[:argv.index('--ros-args')] if '--ros-args' in argv else '--help' in argv:
        print('usage: coils_node [--ros-args --params-file FILE | -p NAME:=VALUE ...]\n\n'
              + __doc__ + '\nparameters:\n' + describe())
        return
    temporary = []
    try:
        ros_argv, warnings, temporary = _prepare_args(argv)
        rclpy.init(args=['coils_node', *ros_argv],
                   signal_handler_options=SignalHandlerOptions.NO)
    except ConfigError as exc:
        print(f'coils_node: not started: {exc}', file=sys.stderr)
        sys.exit(2)
    except Exception as exc:  # rcl refused the arguments: its own message says why
        print(f'coils_node: not started: the ROS arguments were refused: {exc}',
              file=sys.stderr)
        sys.exit(2)
    finally:
        for path in temporary:
            os.unlink(path)
    node = None
    try:
        node = CoilsNode()
        for warning in warnings:
            node.get_logger().warning(warning)
        spin_until_signal(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (CoilsError, ParameterException) as exc:
        print(f'coils_node: not started: {exc}', file=sys.stderr)
        sys.exit(2)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, _already_stopping)
        if node is not None:
            unsafe = node.shutdown()
            print('coils_node: outputs ' + ('zero and off' if not unsafe else
                                            'NOT confirmed zero and off: ' + '; '.join(unsafe)
                                            + ': check the supplies'),
                  file=sys.stderr, flush=True)
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
