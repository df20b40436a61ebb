"""
scripts/rig-command: one command to a running rig (simulated or real), from a terminal.

    scripts/rig-command field 0 0.010 0      # /coils/field_cmd, tesla, frame coils: held
                                             # (re-sent at 5 Hz) until Ctrl-C
    scripts/rig-command home                 # /inserter/home ("zero is here")
    scripts/rig-command insert 0.030         # /inserter/target, metre
    scripts/rig-command estop on|off         # /estop (latched)
    scripts/rig-command enable on|off        # /coils/enable
    scripts/rig-command background           # /vision/capture_background: the empty scene
    scripts/rig-command watch                # /sim/shape's tip, /vision/tip, /sim/contact

Where a lab PC has ROS 2, ``ros2 topic pub`` and ``ros2 service call`` do the same; this is
for the machines without the ros2 command line. Each command waits (with a deadline) until
the rig has a subscriber or server for it, and says what it did. coils_node ramps the field
to zero when no command came for ``watchdog_s`` (1 s): ``field`` therefore holds the field
by sending it again at 5 Hz until Ctrl-C (``--once``: one command, gone after watchdog_s).
``--axis backbone`` sends home and insert to the backbone stage. Exit 0 done, 1 the rig
refused or did not answer, 2 a usage error.
"""

import argparse
import math
import os
import signal
import sys
import threading
import time

from geometry_msgs.msg import Vector3Stamped
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Bool, Float64
from std_srvs.srv import SetBool, Trigger
from tentacle_common import contract
from tentacle_common.discovery import private_by_default
from tentacle_common.driver_node import client, publisher, subscription
from tentacle_common.waiting import wait_for

DISCOVERY_S = 10.0   # how long to wait for the rig to be seen, by default


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='rig-command',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('--axis', default='inserter', help='home and insert: which stage')
    parser.add_argument('--wait-s', type=float, default=DISCOVERY_S,
                        help=f'wait this long for the rig to be seen (default {DISCOVERY_S:g})')
    sub = parser.add_subparsers(dest='command', required=True)
    field = sub.add_parser('field', help='command a field, tesla (frame coils)')
    for name in 'xyz':
        field.add_argument(f'b{name}', type=float, metavar=f'B{name.upper()}')
    field.add_argument('--once', action='store_true',
                       help="one command (coils_node's watchdog ramps it down after 1 s)")
    sub.add_parser('home', help='make where the stage stands its zero')
    sub.add_parser('background', help="the tracker's next frame is the empty scene (call it "
                   'with nothing inserted)')
    insert = sub.add_parser('insert', help='move the stage to a position, metre')
    insert.add_argument('position_m', type=float)
    for name in ('estop', 'enable'):
        switch = sub.add_parser(name, help=f'{name} on or off')
        switch.add_argument('state', choices=('on', 'off'))
    watch = sub.add_parser('watch', help='print the tip, truth and tracked, until Ctrl-C')
    watch.add_argument('--rate', type=float, default=2.0, help='lines per second')
    return parser


def _publisher_seen(node, topic, wait_s):
    """Return (publisher, None) once the rig subscribes to topic; (None, why) if it does not."""
    pub = publisher(node, topic)
    if not wait_for(lambda: pub.get_subscription_count() > 0, wait_s):
        return None, f'no subscriber to {topic.name} in {wait_s:g} s: is the rig up?'
    return pub, None


def _published(node, topic, msg, wait_s):
    pub, problem = _publisher_seen(node, topic, wait_s)
    if problem:
        return problem
    pub.publish(msg)
    time.sleep(0.2)   # let a reliable publication go out before the node goes away
    return None


def _called(node, srv, request, wait_s):
    handle = client(node, srv)
    if not handle.wait_for_service(timeout_sec=wait_s):
        return False, f'no {srv.name} in {wait_s:g} s: is the rig up?'
    future = handle.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=60.0)
    if not future.done():
        return False, f'{srv.name}: no answer in 60 s'
    return future.result().success, future.result().message


def run(node, opts):
    """Carry out one command; return (ok, what to say)."""
    if opts.command == 'field':
        b = (opts.bx, opts.by, opts.bz)
        if not all(math.isfinite(v) for v in b):
            return False, f'field {b}: three finite numbers, tesla'
        msg = Vector3Stamped()
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.header.frame_id = contract.COILS_FRAME
        msg.vector.x, msg.vector.y, msg.vector.z = b
        pub, problem = _publisher_seen(node, contract.FIELD_CMD, opts.wait_s)
        if problem:
            return False, problem
        pub.publish(msg)
        what = f'field [{", ".join(f"{v * 1e3:g}" for v in b)}] mT'
        if opts.once:
            time.sleep(0.2)
            return True, f'{what} commanded once (coils_node logs a refusal)'
        print(f'rig-command: holding {what} (re-sent at 5 Hz); Ctrl-C to stop', flush=True)
        stop = until_ctrl_c()
        while not stop.wait(0.2):
            msg.header.stamp = node.get_clock().now().to_msg()
            pub.publish(msg)
        return True, f'stopped holding {what}: it ramps to zero within watchdog_s'
    if opts.command == 'insert':
        problem = _published(node, contract.axis_target(opts.axis),
                             Float64(data=opts.position_m), opts.wait_s)
        return problem is None, problem or (f'{opts.axis} target {opts.position_m:g} m sent '
                                            '(inserter_node logs a refusal)')
    if opts.command == 'estop':
        problem = _published(node, contract.ESTOP, Bool(data=opts.state == 'on'),
                             opts.wait_s)
        return problem is None, problem or f'estop {opts.state}'
    if opts.command == 'home':
        return _called(node, contract.axis_service(opts.axis, 'home'), Trigger.Request(),
                       opts.wait_s)
    if opts.command == 'background':
        return _called(node, contract.VISION_CAPTURE_BACKGROUND, Trigger.Request(),
                       opts.wait_s)
    if opts.command == 'enable':
        return _called(node, contract.COILS_ENABLE, SetBool.Request(data=opts.state == 'on'),
                       opts.wait_s)
    return watch(node, opts.rate)


def until_ctrl_c():
    """Return an Event that Ctrl-C (or SIGTERM) sets from now on."""
    # A flag, not KeyboardInterrupt: raised inside rclpy (a publish, a take), that comes out
    # of its C++ layer as a RuntimeError.
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop


def watch(node, rate_hz):
    """Print the latest truth, tracked tip and contact until Ctrl-C."""
    stop = until_ctrl_c()
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    latest = {}
    subscription(node, contract.SIM_SHAPE, lambda m: latest.__setitem__('shape', m))
    subscription(node, contract.VISION_TIP, lambda m: latest.__setitem__('tip', m))
    subscription(node, contract.SIM_CONTACT, lambda m: latest.__setitem__('contact', m))
    subscription(node, contract.FIELD, lambda m: latest.__setitem__('field', m))
    next_at = time.monotonic()
    while not stop.is_set():
        executor.spin_once(timeout_sec=0.05)
        if time.monotonic() < next_at:
            continue
        next_at += 1.0 / rate_hz
        parts = []
        if 'field' in latest:
            v = latest['field'].vector
            parts.append(f'field [{v.x * 1e3:6.2f} {v.y * 1e3:6.2f} {v.z * 1e3:6.2f}] mT')
        if 'shape' in latest and latest['shape'].poses:
            p = latest['shape'].poses[-1].pose.position
            parts.append(f'tip (truth) [{p.x * 1e3:6.2f} {p.y * 1e3:6.2f} {p.z * 1e3:6.2f}] mm')
        if 'tip' in latest:
            p = latest['tip'].pose.position
            parts.append(f'tip (tracked) [{p.x * 1e3:6.2f} {p.y * 1e3:6.2f}] mm')
        if 'contact' in latest:
            count, depth = latest['contact'].position
            parts.append(f'contact {int(count)} ({depth * 1e3:.2f} mm)')
        print('  '.join(parts) or 'nothing heard yet', flush=True)
    executor.shutdown()
    return True, 'stopped watching'


def main(args=None):
    """Parse, start rclpy, run the command; exit 0, 1 or 2."""
    opts = build_parser().parse_args(args)
    if not contract.is_name_token(opts.axis):
        print(f'rig-command: --axis {opts.axis!r} is not one ROS name token', file=sys.stderr)
        sys.exit(2)
    private_by_default(os.environ)   # the rig's domain, as scripts/rig sets it
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)   # Ctrl-C is ours
    node = rclpy.create_node('rig_command')
    try:
        ok, message = run(node, opts)
    except KeyboardInterrupt:   # while waiting for the rig or its answer
        ok, message = False, f'interrupted: {opts.command} not confirmed'
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    print(f'rig-command: {message}', file=sys.stdout if ok else sys.stderr)
    sys.exit(0 if ok else 1)


if __name__ == '__main__':
    main()
