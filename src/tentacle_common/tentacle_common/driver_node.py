"""
ROS glue every node shares: the contract's topics, parameters, logging, diagnostics, spin.

The only module of tentacle_common that imports rclpy. ``publisher``, ``subscription``,
``service`` and ``client`` make the endpoints of tentacle_common.contract's rows, with their
types and QoS (nodes, tests, benches and scripts alike). A driver node declares its table
with ``declare_parameters``, forwards its pure code's logging with ``RosLogHandler``, builds
one DiagnosticStatus per device with ``diagnostic_status``, starts rclpy with
``init_checked`` (its parameters checked against the table first) and spins with
``spin_until_signal``, after which it runs its safe stop undisturbed by further signals;
``run_node`` does all of that for a node's ``main``.
"""

import faulthandler
import importlib
import logging
import os
import signal
import sys
import tempfile
import threading

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from tentacle_common.errors import ConfigError, DriverError
from tentacle_common.params import check_ros_args, describe, out_of_range
import yaml


def interface(type_name):
    """Return the message or service class of 'pkg/msg/Name' or 'pkg/srv/Name'."""
    package, kind, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


def qos_profile(qos):
    """Return the rclpy QoSProfile of a contract.Qos row."""
    return QoSProfile(
        depth=qos.depth, history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE if qos.reliable
        else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.latched
        else DurabilityPolicy.VOLATILE)


def publisher(node, topic, qos=None):
    """Create a publisher for a contract.Topic (its own QoS unless qos, a Qos row, is given)."""
    return node.create_publisher(interface(topic.msg_type), topic.name,
                                 qos_profile(qos or topic.qos))


def subscription(node, topic, callback, qos=None):
    """Create a subscription to a contract.Topic (its own QoS unless qos is given)."""
    return node.create_subscription(interface(topic.msg_type), topic.name, callback,
                                    qos_profile(qos or topic.qos))


def service(node, srv, callback):
    """Create the server of a contract.Service."""
    return node.create_service(interface(srv.srv_type), srv.name, callback)


def client(node, srv):
    """Create a client of a contract.Service."""
    return node.create_client(interface(srv.srv_type), srv.name)


LEVELS = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN,
          'error': DiagnosticStatus.ERROR}


def list_range_check(table):
    """
    Return an on-set-parameters callback refusing a list element outside its row's range.

    rcl's descriptor ranges apply to scalars only; rclpy runs this callback at declare time
    (a refused override raises InvalidParameterValueException) and on every later set.
    """
    ranged = {p.name: p for p in table if p.low is not None and isinstance(p.default, list)}

    def check(parameters):
        for parameter in parameters:
            p = ranged.get(parameter.name)
            problem = out_of_range(p, list(parameter.value)) if p is not None else ''
            if problem:
                return SetParametersResult(successful=False, reason=f'{p.name}: {problem}')
        return SetParametersResult(successful=True)
    return check


def declare_parameters(node, table, read_only=True):
    """
    Declare every row of a parameter table with a descriptor; return {name: value}.

    Ranges hold for scalars (the descriptor's) and for each element of a list
    (``list_range_check``), at declare time and on any set.

    :param read_only: the drivers' parameters are fixed for the node's life
    :raises rclpy.exceptions.ParameterException: a value rcl or the range check refuses
    """
    node.add_on_set_parameters_callback(list_range_check(table))
    values = {}
    for p in table:
        descriptor = ParameterDescriptor(description=p.description, read_only=read_only)
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


def diagnostic_status(name, hardware_id, level, message, values=None):
    """Return a DiagnosticStatus; level is 'ok', 'warn' or 'error', values a dict."""
    status = DiagnosticStatus(name=name, hardware_id=hardware_id, level=LEVELS[level],
                              message=message)
    status.values = [KeyValue(key=str(k), value=str(v)) for k, v in (values or {}).items()]
    return status


def wants_help(argv):
    """Return True when --help comes before any --ros-args."""
    head = argv[:argv.index('--ros-args')] if '--ros-args' in argv else argv
    return '--help' in head


def node_name_of(argv, default):
    """
    Return the node's name as rcl will give it: ``-r __node:=NAME`` in --ros-args, or default.

    Its params-file section and its log lines use that name: two instances of one
    executable (the inserter and the backbone axis) run under two names.
    """
    name, in_ros_args = default, False
    for i, arg in enumerate(argv):
        if arg == '--ros-args':
            in_ros_args = True
        elif arg == '--':
            in_ros_args = False
        elif in_ros_args and arg in ('-r', '--remap') and i + 1 < len(argv):
            target, sep, value = argv[i + 1].partition(':=')
            if sep and target in ('__node', '__name', f'{default}:__node', f'{default}:__name'):
                name = value
    return name


def init_checked(argv, node_name, table):
    """
    Check --ros-args against the parameter table, then start rclpy without its handlers.

    Params files that needed conversions (integers for doubles) are handed to rcl as a
    normalised copy, removed once rcl has read it.

    :return: the warnings to log once the node exists (misspelt parameters)
    :raises ConfigError: a params file that is missing, unreadable or has a wrong type, or
        ROS arguments that rcl refuses
    """
    checked, warnings, rewrite = check_ros_args(argv, node_name, table)
    temporary = []
    try:
        for index, document in rewrite.items():
            handle = tempfile.NamedTemporaryFile('w', prefix=f'{node_name}_params_',
                                                 suffix='.yaml', delete=False)
            with handle:
                yaml.safe_dump(document, handle)
            temporary.append(handle.name)
            checked[index] = handle.name
        try:
            rclpy.init(args=[node_name, *checked],
                       signal_handler_options=SignalHandlerOptions.NO)
        except Exception as exc:  # rcl refused the arguments: its own message says why
            raise ConfigError(f'the ROS arguments were refused: {exc}') from None
    finally:
        for path in temporary:
            os.unlink(path)
    return warnings


def ignore_further_signals(name):
    """From now on SIGINT and SIGTERM only print that the safe stop goes on."""
    def already_stopping(_signum, _frame):
        # os.write: a print could re-enter the stderr buffer the main thread is writing to.
        os.write(2, f'{name}: already stopping safely: signal ignored\n'.encode())

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, already_stopping)


def ignore_signals_to_exit():
    """
    Ignore SIGINT and SIGTERM at the OS level for the rest of the process: call once stopped.

    Python resets its own handlers to the default while the interpreter finalises (rclpy's
    and Fast DDS's teardown comes after), so a signal then would end a clean, confirmed stop
    as a kill by that signal. SIG_IGN is the one disposition it leaves in place.
    """
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)


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
        ignore_further_signals(node.get_name())
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
        if not received:  # after a signal the safe stop follows: keep ignoring them
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    return received[0] if received else 0


def run_node(argv, node_name, table, doc, make_node, stop_safely):
    """
    Run a driver node's life: --help, a checked start, spin until a signal, its safe stop.

    :param argv: the command line after the program name
    :param table: the node's parameter table (tentacle_common.params.Param rows)
    :param doc: what --help prints above the table (the node module's docstring)
    :param make_node: returns the node (raising DriverError or ParameterException: exit 2)
    :param stop_safely: node -> the line printed at exit ('<node_name>: <line>'), after the
        actuators were brought to their safe state, read back; '<node_name>: running' is
        printed once the node is built and spins; a signal while it is built exits 130
    """
    if wants_help(argv):
        print(f'usage: {node_name} [--ros-args --params-file FILE | -p NAME:=VALUE ...'
              ' | -r __node:=NAME]\n\n' + doc + '\nparameters:\n' + describe(table))
        return
    node_name = node_name_of(argv, node_name)
    try:
        warnings = init_checked(argv, node_name, table)
    except ConfigError as exc:
        print(f'{node_name}: not started: {exc}', file=sys.stderr)
        sys.exit(2)
    # `kill -USR1 <pid>` prints every thread's stack to stderr without stopping the node, as
    # the driver child processes do (rclpy takes SIGINT and SIGTERM only).
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    node = None
    try:
        node = make_node()
        for warning in warnings:
            node.get_logger().warning(warning)
        # What a bringup waits for (tentacle_rig.bringup): built, its devices opened.
        print(f'{node_name}: running', file=sys.stderr, flush=True)
        spin_until_signal(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        if node is None:   # interrupted while being built: no safe stop to confirm, say so
            ignore_further_signals(node_name)
            print(f'{node_name}: interrupted while starting: no safe stop confirmed',
                  file=sys.stderr, flush=True)
            sys.exit(130)
    except (DriverError, ParameterException) as exc:
        print(f'{node_name}: not started: {exc}', file=sys.stderr)
        sys.exit(2)
    finally:
        ignore_further_signals(node_name)
        if node is not None:
            print(f'{node_name}: {stop_safely(node)}', file=sys.stderr, flush=True)
            node.destroy_node()
        rclpy.try_shutdown()
        ignore_signals_to_exit()
