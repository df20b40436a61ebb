"""
scripts/rig: bring the whole rig up from one process table, and down safely.

    scripts/rig --sim config/scenes/pancreatic_duct.yaml
    scripts/rig --sim config/scenes/pancreatic_duct.yaml --schedule out/schedule.yaml \
                --record out/bags            # + player_node and recorder_node
    scripts/rig --real config/lab            # coils.yaml, inserter.yaml, ... found there

``--sim`` starts sim_node, coils_node, inserter_node (backbone_node where the scene has a
backbone) and tracker_node (bringup.sim_table); ``--real`` starts the drivers whose params
files a folder holds (bringup.real_table). ``--schedule`` adds player_node (the simulated
tentacle is then the one made to that plan; on the real rig the folder's player.yaml is
used), and ``--record DIR`` recorder_node, writing DIR/<date-time> (a rosbag2 directory
with one MCAP file). Play with ``scripts/rig-command play``. Each node is its own process,
its output in ``--logs``. Ctrl-C (or SIGTERM) stops the player first, then the drivers, each
confirming its safe state (supplies at zero and off, axes stopped), then the tracker, the
recorder (its bag closed and readable) and the simulator; further Ctrl-C only say that the
stop goes on. If a node dies on its own the rig is stopped the same way. DDS stays private
(tentacle_common.discovery): ROS_DOMAIN_ID 57 and discovery on this machine only
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) unless the environment sets them: set
ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET and a ROS_DOMAIN_ID of the lab's to let other machines
see and command the rig.

Exit status: 0 when every driver confirmed its safe stop; 1 when one did not, or a node
died; 2 for a usage error or a rig that did not come up.
"""

import argparse
import os
import pathlib
import signal
import sys
import threading
import time

from tentacle_planner.player_params import MODES

USAGE_EXIT, UNSAFE_EXIT = 2, 1
ROOT = pathlib.Path(__file__).resolve().parents[3]


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(
        prog='rig', description=__doc__.strip().split('\n')[0],
        epilog='Ctrl-C stops the drivers first, then the simulator.')
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument('--sim', metavar='SCENE', help='a scene file: run the simulated rig')
    mode.add_argument('--real', metavar='CONFIG',
                      help="a folder of the lab's params files: coils.yaml, inserter.yaml, "
                      'backbone.yaml, camera.yaml, tracker.yaml (those present are run)')
    parser.add_argument('--device-dir', help="--sim: sim_node's device folder (default "
                        "config/sim/sim.yaml's, /tmp/tentacle_sim)")
    parser.add_argument('--no-tracker', action='store_true', help='--sim: no tracker_node')
    parser.add_argument('--sim-param', action='append', default=[], metavar='NAME:=VALUE',
                        help='--sim: a sim_node parameter (repeatable), e.g. camera_rate:=15')
    parser.add_argument('--schedule', metavar='FILE', help='run player_node for this schedule '
                        '(tentacle-plan --out DIR writes DIR/schedule.yaml)')
    parser.add_argument('--mode', choices=MODES,
                        help="--schedule: the player's mode (default its params file's)")
    parser.add_argument('--record', metavar='DIR', help='record the session into '
                        'DIR/<date-time> (rosbag2, MCAP)')
    parser.add_argument('--logs', help="folder for the nodes' output (default "
                        '/tmp/tentacle_rig/<date-time>)')
    return parser


def table_of(opts, parser):
    """Return the process table the options ask for (a usage error if they do not fit)."""
    from tentacle_rig import bringup
    if opts.mode and not opts.schedule:
        parser.error('--mode goes with --schedule')
    player = {'mode': opts.mode} if opts.mode else None
    record = None if opts.record is None else \
        str(pathlib.Path(opts.record) / time.strftime('%Y%m%d-%H%M%S'))
    if opts.real:
        if opts.device_dir or opts.no_tracker or opts.sim_param:
            parser.error('--device-dir, --no-tracker and --sim-param go with --sim')
        return bringup.real_table(opts.real, ROOT, opts.schedule, player, record)
    params = {}
    for item in opts.sim_param:
        name, sep, value = item.partition(':=')
        if not sep or not name:
            parser.error(f'--sim-param {item!r}: expected NAME:=VALUE')
        params[name] = value
    return bringup.sim_table(opts.sim, ROOT, opts.device_dir, not opts.no_tracker,
                             opts.schedule, player, record, **params)


def main(args=None):
    """Bring the rig up, wait for Ctrl-C or a death, bring it down; return the exit code."""
    parser = build_parser()
    opts = parser.parse_args(args)
    from tentacle_common.discovery import private_by_default
    from tentacle_planner.errors import PlanInputError
    from tentacle_rig.bringup import Rig, RigError
    from tentacle_sim.params import DEFAULT_DEVICE_DIR
    try:
        table = table_of(opts, parser)
    except (FileNotFoundError, PlanInputError) as exc:
        print(f'rig: {exc}', file=sys.stderr)
        return USAGE_EXIT
    print(f'rig: {private_by_default(os.environ)}', flush=True)
    if opts.sim:   # a background of another scene would be taken for this one's
        stale = pathlib.Path(opts.device_dir or DEFAULT_DEVICE_DIR) / 'background.png'
        stale.unlink(missing_ok=True)
    logs = pathlib.Path(opts.logs or f'/tmp/tentacle_rig/{time.strftime("%Y%m%d-%H%M%S")}')
    stop = threading.Event()

    def on_signal(signum, _frame):
        if stop.is_set():
            os.write(2, b'rig: already stopping: drivers first, then the simulator\n')
        stop.set()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    say = lambda line: print(line, flush=True)  # noqa: E731
    try:
        rig = Rig(table, logs, ROOT, say, cancelled=stop.is_set)
    except RigError as exc:
        print(f'rig: did not come up: {exc}', file=sys.stderr)
        return USAGE_EXIT
    say(f'rig: up ({", ".join(e.name for e in table)}); logs in {logs}. '
        'Ctrl-C stops the drivers first, then the simulator.')
    if opts.sim and not opts.no_tracker:
        say('rig: before inserting, let the tracker see the empty scene: '
            'scripts/rig-command background')
    died = []
    while not stop.wait(0.2):
        died = [name for name in [e.name for e in table] if name not in rig.alive()]
        if died:
            say(f'rig: {", ".join(died)} exited on its own (see {logs}): stopping the rig')
            break
    report = rig.stop()
    unsafe = [name for name, _, _, safe in report if not safe]
    if unsafe:
        say(f'rig: NOT confirmed safe: {", ".join(unsafe)}: check those devices')
    return UNSAFE_EXIT if unsafe or died else 0


if __name__ == '__main__':
    sys.exit(main())
