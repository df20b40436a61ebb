"""
scripts/rig-command: one command to a running rig (simulated or real), from a terminal.

    scripts/rig-command field 0 0.010 0      # /coils/field_cmd, tesla, frame coils: held
                                             # (re-sent at 5 Hz) until Ctrl-C
    scripts/rig-command home                 # /inserter/home ("zero is here")
    scripts/rig-command insert 0.030         # /inserter/target, metre: waits until there
    scripts/rig-command estop on|off         # /estop (latched)
    scripts/rig-command enable on|off        # /coils/enable
    scripts/rig-command background           # /vision/capture_background: the empty scene
    scripts/rig-command play [SCHEDULE] [--mode closed_loop] [--retract]
                                             # player_node: plays, prints progress
    scripts/rig-command pause|resume|abort   # player_node: the run under way
    scripts/rig-command watch                # /sim/shape's tip, /vision/tip, /sim/contact

Where a lab PC has ROS 2, ``ros2 topic pub`` and ``ros2 service call`` do the same; this is
for the machines without the ros2 command line. It is tentacle_rig.commander_node's
RigCommander, as a lab script would use it: every wait has a deadline, and the command says
what happened. coils_node ramps the field to zero when no command came for ``watchdog_s``
(1 s): ``field`` therefore holds the field until Ctrl-C (``--once``: set, then let go).
Ctrl-C during ``play`` pauses the run (the field and the stage held where they are): then
``resume`` or ``abort`` it. ``--axis backbone`` sends home and insert to the backbone
stage. Exit 0 done, 1 the rig refused, did not answer, or the run paused or aborted, 2 a
usage error.
"""

import argparse
import math
import signal
import sys
import threading

from tentacle_common import contract
from tentacle_common.driver_node import subscription
from tentacle_planner.player_params import MODES

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
                       help="set it, then let go (coils_node's watchdog ramps it down after 1 s)")
    sub.add_parser('home', help='make where the stage stands its zero')
    sub.add_parser('background', help="the tracker's next frame is the empty scene (call it "
                   'with nothing inserted)')
    insert = sub.add_parser('insert', help='move the stage to a position, metre')
    insert.add_argument('position_m', type=float)
    for name in ('estop', 'enable'):
        switch = sub.add_parser(name, help=f'{name} on or off')
        switch.add_argument('state', choices=('on', 'off'))
    play = sub.add_parser('play', help='play a schedule with player_node (default: the one '
                          'it was given)')
    play.add_argument('schedule', nargs='?', help='a schedule file (tentacle-plan --out)')
    play.add_argument('--mode', choices=MODES, help="the player's mode (default: as it is)")
    play.add_argument('--retract', action='store_true', help='play it backwards')
    for verb in ('pause', 'resume', 'abort'):
        sub.add_parser(verb, help=f'{verb} the run under way')
    watch = sub.add_parser('watch', help='print the tip, truth and tracked, until Ctrl-C')
    watch.add_argument('--rate', type=float, default=2.0, help='lines per second')
    return parser


def until_ctrl_c():
    """Return an Event that Ctrl-C (or SIGTERM) sets from now on."""
    # A flag, not KeyboardInterrupt: raised inside rclpy (a publish, a take), that comes out
    # of its C++ layer as a RuntimeError.
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop


def run(rig, opts):
    """Carry out one command on a RigCommander; return (ok, what to say)."""
    wait = opts.wait_s
    if opts.command == 'field':
        b = (opts.bx, opts.by, opts.bz)
        if not all(math.isfinite(v) for v in b):
            return False, f'field {b}: three finite numbers, tesla'
        what = f'field [{", ".join(f"{v * 1e3:g}" for v in b)}] mT'
        stop = until_ctrl_c()
        result = rig.set_field(b, timeout_s=wait)
        if not result or opts.once:
            rig.release_field()
            return bool(result), f'{what}: {result.message}'
        print(f'rig-command: holding {what} (re-sent at 5 Hz); Ctrl-C to stop', flush=True)
        stop.wait()
        rig.release_field()
        return True, f'stopped holding {what}: it ramps to zero within watchdog_s'
    simple = {'insert': lambda: rig.move_axis(opts.axis, opts.position_m),
              'home': lambda: rig.home(opts.axis, wait),
              'background': lambda: rig.capture_background(max(wait, 20.0)),
              'estop': lambda: rig.estop(opts.state == 'on', wait),
              'enable': lambda: rig.enable_coils(opts.state == 'on', wait),
              'pause': lambda: rig.player('pause', wait),
              'resume': lambda: rig.player('resume', wait),
              'abort': lambda: rig.player('abort', wait)}
    if opts.command in simple:
        result = simple[opts.command]()
        return bool(result), result.message or result.outcome.value
    if opts.command == 'play':
        return play(rig, opts)
    return watch(rig, opts.rate)


def play(rig, opts):
    """Play a schedule, printing progress; Ctrl-C pauses the run."""
    stop = until_ctrl_c()
    params = {'mode': opts.mode} if opts.mode else {}
    if opts.schedule:
        params['schedule'] = opts.schedule
    for check in (lambda: rig.wait_for_player(opts.wait_s),
                  lambda: rig.set_player(**params) if params else True,
                  lambda: rig.player('retract' if opts.retract else 'start')):
        result = check()
        if not result:
            return False, result.message
    outcome = []

    def printed(p):
        print(f'rig-command: step {p.step}/{p.steps}: {p.inserted_m * 1e3:.1f} mm inserted, '
              f'tracked shape {p.shape_rms_m * 1e3:.2f} mm RMS', flush=True)
    waiter = threading.Thread(target=lambda: outcome.append(
        rig.wait_for_run(24 * 3600.0, printed)), daemon=True)
    waiter.start()
    while waiter.is_alive() and not stop.wait(0.1):
        pass
    if not outcome:
        paused = rig.player('pause', opts.wait_s)
        return False, (f'Ctrl-C: {paused.message}: rig-command resume, or abort'
                       if paused else f'Ctrl-C: the pause was not confirmed: {paused.message}')
    return bool(outcome[0]), f'the run: {outcome[0].outcome.value}: {outcome[0].message}'


def watch(rig, rate_hz):
    """Print the latest truth, tracked tip and contact until Ctrl-C."""
    stop = until_ctrl_c()
    latest = {}
    for key, topic in (('shape', contract.SIM_SHAPE), ('tip', contract.VISION_TIP),
                       ('contact', contract.SIM_CONTACT)):
        subscription(rig, topic, lambda m, k=key: latest.__setitem__(k, m))
    while not stop.wait(1.0 / rate_hz):
        parts = []
        field = rig.field_t()
        if field is not None:
            parts.append('field [' + ' '.join(f'{v * 1e3:6.2f}' for v in field) + '] mT')
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
    return True, 'stopped watching'


def main(args=None):
    """Parse, start the RigCommander, run the command; exit 0, 1 or 2."""
    opts = build_parser().parse_args(args)
    if not contract.is_name_token(opts.axis):
        print(f'rig-command: --axis {opts.axis!r} is not one ROS name token', file=sys.stderr)
        sys.exit(2)
    from tentacle_rig.commander_node import RigCommander   # starts rclpy: after the usage
    rig = RigCommander('rig_command')
    try:
        ok, message = run(rig, opts)
    except KeyboardInterrupt:   # while waiting for the rig or its answer
        ok, message = False, f'interrupted: {opts.command} not confirmed'
    finally:
        rig.close()
    print(f'rig-command: {message}', file=sys.stdout if ok else sys.stderr)
    sys.exit(0 if ok else 1)


if __name__ == '__main__':
    main()
