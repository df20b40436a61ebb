"""
tentacle-plan: a magnetisation profile and field schedule for a scene, verified.

    tentacle-plan --scene config/scenes/NAME.yaml --out DIR [--seed N] [--starts N]
                  [--baseline tip-driven] [--robust]

Writes DIR/schedule.yaml (DESIGN.md's schema) and DIR/plan.png and prints a summary. Exit
code 0 for a plan without flags, 3 when the plan is flagged (an unstable or unconverged
step, a broken limit: written, and said so, never as fine), 2 for bad input, 130 after
Ctrl-C (the best plan so far is written, marked interrupted).
"""

import argparse
import sys

from tentacle_planner.errors import PlanInputError
from tentacle_planner.planner import plan_scene
from tentacle_planner.scene import load_scene
from tentacle_planner.schedule import summary, write_schedule


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='tentacle-plan',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('--scene', required=True, help='scene YAML file (config/scenes/)')
    parser.add_argument('--out', required=True, metavar='DIR',
                        help='where schedule.yaml and plan.png go')
    parser.add_argument('--seed', type=int, default=0, help='seeds the multi-start')
    parser.add_argument('--starts', type=int, default=8, help='random starts (default 8)')
    parser.add_argument('--iterations', type=int, default=100,
                        help='model evaluations per start (default 100)')
    parser.add_argument('--baseline', choices=('tip-driven',), default=None,
                        help='tip-driven: every magnetisation axial, fields only')
    parser.add_argument('--robust', action='store_true',
                        help='plan against every perturbed model, not only the nominal one')
    return parser


def _progress(stage, done, total, best):
    bar = '#' * round(20 * done / max(total, 1))
    print(f'\r{stage}: [{bar:<20}] {done}/{total} starts, best objective {best:.3g}',
          end='' if done < total else '\n', file=sys.stderr, flush=True)


def main(args=None):
    """Plan, write and summarise; return the exit code."""
    opts = build_parser().parse_args(args)
    if opts.starts < 0 or opts.iterations < 1:
        print('tentacle-plan: --starts must be >= 0 and --iterations >= 1', file=sys.stderr)
        return 2
    try:
        scene = load_scene(opts.scene)
    except PlanInputError as exc:
        print(f'tentacle-plan: {exc}', file=sys.stderr)
        return 2
    result = plan_scene(scene, seed=opts.seed, starts=opts.starts, iterations=opts.iterations,
                        tip_driven=opts.baseline == 'tip-driven', robust=opts.robust,
                        progress=_progress)
    path = write_schedule(opts.out, result)
    print(summary(result))
    print(f'wrote {path} and {path.parent / "plan.png"}')
    if result.interrupted:
        return 130
    return 3 if result.flags else 0


if __name__ == '__main__':
    sys.exit(main())
