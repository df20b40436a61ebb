"""
tentacle-plan: a magnetisation profile and field schedule for a scene, verified.

    tentacle-plan --scene config/scenes/NAME.yaml --out DIR [--seed N] [--starts N]
                  [--baseline tip-driven] [--robust] [--first-stage torque-balance]
    tentacle-plan --tentacle FILE --path FILE --out DIR [--steps M,M,...] [limits...]

Writes DIR/schedule.yaml (DESIGN.md's schema) and DIR/plan.png and prints a summary. Exit
code 0 for a plan without flags, 3 when the plan is flagged (an unstable or unconverged
step, a broken limit: written, and said so, never as fine), 2 for bad input, 130 after
Ctrl-C (the best plan so far is written, marked interrupted).
"""

import argparse
import sys

from tentacle_planner.errors import PlanInputError
from tentacle_planner.planner import plan_scene
from tentacle_planner.scene import load_scene, scene_of
from tentacle_planner.schedule import summary, write_schedule


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='tentacle-plan',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('--scene', help='scene YAML file (config/scenes/)')
    files = parser.add_argument_group(
        'without a scene file', 'a tentacle and a path file, the limits as options (omitted: '
        'no such limit, as in a scene file)')
    files.add_argument('--tentacle', metavar='FILE', help='tentacle file (config/tentacles/)')
    files.add_argument('--path', metavar='FILE',
                       help='path file: .csv (header names the unit), .npy, .mrk.json, .fcsv')
    files.add_argument('--frame', choices=('rig', 'image'),
                       help="the path's frame (default: the file's own)")
    files.add_argument('--steps', type=_lengths, metavar='M,M,...',
                       help='inserted length at each key step, m (default: every segment end)')
    files.add_argument('--playback-step', type=float, metavar='M',
                       help='also plan every intermediate step this far apart, m')
    files.add_argument('--max-field', type=float, metavar='T', help='per coil axis, T')
    files.add_argument('--max-total-field', type=float, metavar='T', help='|B|, T')
    files.add_argument('--max-field-change', type=float, metavar='T',
                       help='per axis between steps, T')
    files.add_argument('--dof', type=int, choices=(1, 3), default=3,
                       help='joint model: 1 planar, 3 bend-bend-twist (default 3)')
    files.add_argument('--max-neighbour-angle', type=float, metavar='DEG',
                       help='between neighbouring magnetisations, deg')
    files.add_argument('--planar-magnetisation', action='store_true',
                       help="magnetise in the link's x-y plane only")
    parser.add_argument('--out', required=True, metavar='DIR',
                        help='where schedule.yaml and plan.png go')
    parser.add_argument('--seed', type=int, default=0, help='seeds the multi-start')
    parser.add_argument('--starts', type=int, default=8, help='random starts (default 8)')
    parser.add_argument('--iterations', type=int, default=100,
                        help='model evaluations per start (default 100)')
    parser.add_argument('--baseline', choices=('tip-driven',), default=None,
                        help='tip-driven: every magnetisation axial, fields only')
    parser.add_argument('--first-stage', choices=('torque-balance',), default=None,
                        help="fit each start on the thesis' torque balance at the target "
                        'shape first (fast, blind to stability), then on the forward model')
    parser.add_argument('--robust', action='store_true',
                        help='plan against every perturbed model, not only the nominal one')
    return parser


def _lengths(text):
    try:
        return [float(v) for v in text.split(',')]
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected lengths in m separated by commas, got '
                                         f'{text!r}') from None


def _scene(opts):
    """Return the Scene of the options: a scene file, or a tentacle and a path file."""
    if opts.scene:
        return load_scene(opts.scene)
    coil = {'max_field_t': opts.max_field, 'max_total_field_t': opts.max_total_field,
            'max_field_change_t': opts.max_field_change}
    magnetisation = {'planar': opts.planar_magnetisation,
                     'max_neighbour_angle_deg': opts.max_neighbour_angle}
    return scene_of(opts.tentacle, opts.path, opts.steps, frame=opts.frame,
                    playback_step_m=opts.playback_step, model={'dof': opts.dof},
                    coil={k: v for k, v in coil.items() if v is not None},
                    magnetisation={k: v for k, v in magnetisation.items() if v is not None})


def _progress(stage, done, total, best):
    bar = '#' * round(20 * done / max(total, 1))
    print(f'\r{stage}: [{bar:<20}] {done}/{total} starts, best objective {best:.3g}',
          end='' if done < total else '\n', file=sys.stderr, flush=True)


def main(args=None):
    """Plan, write and summarise; return the exit code."""
    parser = build_parser()
    opts = parser.parse_args(args)
    if opts.starts < 0 or opts.iterations < 1:
        print('tentacle-plan: --starts must be >= 0 and --iterations >= 1', file=sys.stderr)
        return 2
    single = ('tentacle', 'path', 'frame', 'steps', 'playback_step', 'max_field',
              'max_total_field', 'max_field_change', 'max_neighbour_angle')
    if opts.scene and any(getattr(opts, k) is not None for k in single):
        parser.error('--scene takes every setting from the scene file: give it alone, or '
                     '--tentacle and --path with the limits as options')
    if not opts.scene and not (opts.tentacle and opts.path):
        parser.error('give --scene FILE, or --tentacle FILE and --path FILE')
    try:
        scene = _scene(opts)
    except PlanInputError as exc:
        print(f'tentacle-plan: {exc}', file=sys.stderr)
        return 2
    result = plan_scene(scene, seed=opts.seed, starts=opts.starts, iterations=opts.iterations,
                        tip_driven=opts.baseline == 'tip-driven', robust=opts.robust,
                        progress=_progress, first_stage=opts.first_stage == 'torque-balance')
    path = write_schedule(opts.out, result)
    print(summary(result))
    print(f'wrote {path} and {path.parent / "plan.png"}')
    if result.interrupted:
        return 130
    return 3 if result.flags else 0


if __name__ == '__main__':
    sys.exit(main())
