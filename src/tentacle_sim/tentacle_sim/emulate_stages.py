"""
Run emulated linear stages on pseudo-terminals, controlled by JSON lines on stdin.

Start::

    stage_emulator --link-dir /tmp/rig --axes inserter backbone --dialects gcode step1mm

makes a port link per axis (/tmp/rig/inserter, /tmp/rig/backbone), prints one JSON line
``{"ready": true, "ports": {"inserter": "/tmp/rig/inserter", ...}}`` and then answers the
control requests of emulator_control (state, fault, log, quit). Faults: the line's
(no_reply, drop_reply, garble, late [late_s], disconnect [duration_s]) and the gcode
firmware's slow [factor], stall [after_m] and reset; see stage_emulator.py.
"""

import argparse
import os
import sys

from tentacle_inserter import step1mm
from tentacle_sim.emulator_control import line_rate, serve_devices
from tentacle_sim.stage_emulator import GcodeStage, Step1mmStage

MAPPINGS = {'later': step1mm.Mapping(), 'earlier': step1mm.EARLIER}


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='stage_emulator',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('--link-dir', required=True, help='directory for stable port links')
    parser.add_argument('--axes', nargs='+', default=['inserter'], help='one port per axis')
    parser.add_argument('--dialects', nargs='+', choices=('gcode', 'step1mm'),
                        default=['gcode'], help='per axis (one for all, or one each)')
    parser.add_argument('--baud', type=line_rate, default=115200,
                        help='gcode line rate, bit/s (step1mm runs at 9600)')
    parser.add_argument('--accel', type=float, default=0.5,
                        help="the firmware's acceleration, m/s^2")
    parser.add_argument('--steps-per-mm', type=float, default=100.0,
                        help='gcode: until M92 sets it')
    parser.add_argument('--reset-after-halt-s', type=float, default=None,
                        help='gcode: after M112 the firmware restarts by itself this late, s')
    parser.add_argument('--step1mm-speed', type=float, default=0.005,
                        help='step1mm: speed of each 1 mm move, m/s')
    parser.add_argument('--step1mm-mapping', choices=sorted(MAPPINGS), default='later',
                        help="step1mm: later ('2' extends) or earlier ('1' extends) lab code")
    parser.add_argument('--log-dir', default=None, help='write <axis>.jsonl request logs here')
    return parser


def build_stages(opts):
    """Return {axis: started stage emulator} for the parsed options."""
    dialects = opts.dialects * len(opts.axes) if len(opts.dialects) == 1 else opts.dialects
    if len(dialects) != len(opts.axes):
        raise SystemExit(f'stage_emulator: {len(opts.axes)} axes but {len(dialects)} dialects')
    os.makedirs(opts.link_dir, exist_ok=True)
    stages = {}
    for axis, dialect in zip(opts.axes, dialects):
        where = {'link_path': os.path.join(opts.link_dir, axis),
                 'log_path': os.path.join(opts.log_dir, f'{axis}.jsonl') if opts.log_dir
                 else None}
        if dialect == 'gcode':
            stages[axis] = GcodeStage(axis, baud=opts.baud, accel_m_s2=opts.accel,
                                      steps_per_mm=opts.steps_per_mm,
                                      reset_after_halt_s=opts.reset_after_halt_s, **where)
        else:
            stages[axis] = Step1mmStage(axis, mapping=MAPPINGS[opts.step1mm_mapping],
                                        speed_m_s=opts.step1mm_speed, accel_m_s2=opts.accel,
                                        **where)
        stages[axis].start()
    return stages


def main(args=None):
    """Start the stages and serve control requests until told to stop."""
    opts = build_parser().parse_args(args)
    sys.setswitchinterval(2e-4)  # device threads keep the modelled line's timing
    serve_devices(build_stages(opts))


if __name__ == '__main__':
    main()
