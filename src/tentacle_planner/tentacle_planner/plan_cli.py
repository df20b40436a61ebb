"""
tentacle-plan: a magnetisation profile and field schedule for a scene, verified.

    tentacle-plan --scene config/scenes/NAME.yaml --out DIR [--seed N] [--starts N]
                  [--min-gain F] [--baseline tip-driven] [--robust]
                  [--first-stage torque-balance]
    tentacle-plan --tentacle FILE --path FILE --out DIR [--steps M,M,...] [limits...]

Writes DIR/schedule.yaml (DESIGN.md's schema) and DIR/plan.png and prints a summary. Exit
code 0 for a plan without flags, 3 when the plan is flagged (an unstable or unconverged
step, a broken limit: written, and said so, never as fine), 2 for bad input (DIR that
cannot be written is found before planning), 130 after Ctrl-C.

Ctrl-C, in any phase: once a plan exists (the first start fitted, or the first step of
the insertion-order start) the best plan so far is written, marked interrupted, with a flag
naming what was left out (dense playback, the robustness report, the re-check), and said
so; before that, or while the files are written, nothing is written, and that is said. A
run replaces the previous run's schedule.yaml and plan.png in DIR: each is written under a
temporary name and renamed, and the previous picture is removed before the new schedule
goes in, so DIR never holds two runs' files (schedule_writer.py).
"""

import argparse
import os
import pathlib
import sys
import tempfile

from tentacle_planner.errors import PlanInputError
from tentacle_planner.search_defaults import (DEFAULT_ITERATIONS, DEFAULT_MIN_GAIN,
                                              DEFAULT_STARTS)

MAX_STARTS = 10_000       # random starts: each is a fit of its own (seconds)
MAX_ITERATIONS = 100_000  # model evaluations per start
INTERRUPTED = 130         # the shell's code for Ctrl-C (128 + SIGINT)


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
    parser.add_argument('--seed', type=_whole(0), default=0,
                        help='seeds the multi-start: a whole number >= 0')
    parser.add_argument('--starts', type=_whole(1, MAX_STARTS), default=DEFAULT_STARTS,
                        help=f'starts of the multi-start, 1 to {MAX_STARTS} (default '
                        f'{DEFAULT_STARTS})')
    parser.add_argument('--min-gain', type=_fraction, default=DEFAULT_MIN_GAIN,
                        help='end the search once a round of two starts lowers the best '
                        'objective by less than this fraction, 0 to 1, never after the '
                        f'first round (default {DEFAULT_MIN_GAIN:g}; 0: every start, the '
                        'exhaustive search)')
    parser.add_argument('--iterations', type=_whole(1, MAX_ITERATIONS),
                        default=DEFAULT_ITERATIONS,
                        help=f'model evaluations per start, 1 to {MAX_ITERATIONS} (default '
                        f'{DEFAULT_ITERATIONS}; the exhaustive search of before: --starts 8 '
                        '--iterations 100 --min-gain 0)')
    parser.add_argument('--baseline', choices=('tip-driven',), default=None,
                        help='tip-driven: every magnetisation axial, fields only')
    parser.add_argument('--first-stage', choices=('torque-balance',), default=None,
                        help="fit each start on the thesis' torque balance at the target "
                        'shape first (fast, blind to stability), then on the forward model')
    parser.add_argument('--robust', action='store_true',
                        help='plan against every perturbed model, not only the nominal one')
    return parser


def _whole(low, high=None):
    """Return an argparse type: a whole number from low to high (None: no upper bound)."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected a whole number, got {text!r}') from None
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(
                f'{value} is not ' + (f'from {low} to {high}' if high is not None
                                      else f'>= {low}'))
        return value
    return parse


def _fraction(text):
    """Return a number from 0 to 1 (argparse type)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not 0.0 <= value <= 1.0:   # NaN too
        raise argparse.ArgumentTypeError(f'{text} is not from 0 to 1')
    return value


def _lengths(text):
    try:
        return [float(v) for v in text.split(',')]
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected lengths in m separated by commas, got '
                                         f'{text!r}') from None


def _scene(opts):
    """Return the Scene of the options: a scene file, or a tentacle and a path file."""
    from tentacle_planner.scene import load_scene, scene_of
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
    """Draw a progress bar on stderr: starts (with the best objective) or steps (best None)."""
    bar = '#' * round(20 * done / max(total, 1))
    what = 'steps' if best is None else f'starts, best objective {best:.3g}'
    _progress.open = done < total  # a line still to be ended (_say)
    print(f'\r{stage}: [{bar:<20}] {done}/{total} {what}', end='' if done < total else '\n',
          file=sys.stderr, flush=True)


_progress.open = False


def _say(message):
    """Print a message to stderr, on a line of its own after a progress bar."""
    print(('\n' if _progress.open else '') + f'tentacle-plan: {message}', file=sys.stderr)
    _progress.open = False


def output_problem(out, names):
    """
    Return why the folder out cannot take a run's outputs (files named names), or None.

    Tried, not guessed (permissions say little to root, or under /proc): a file is made and
    removed in the folder, or in its nearest existing parent when it is still to be made.
    """
    path = pathlib.Path(out).absolute()
    if path.exists() and not path.is_dir():
        return f'{out} exists and is not a folder'
    for name in names:
        if (path / name).exists() and not (path / name).is_file():
            return f'{path / name} exists and is not a file'
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        return f'{out}: {existing} is not a folder'
    try:
        fd, probe = tempfile.mkstemp(dir=existing, prefix='.tentacle-plan-', suffix='.probe')
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        return f'{out}: cannot write in {existing} ({exc.strerror})'
    return None


def main(args=None):
    """Plan, write and summarise; return the exit code."""
    parser = build_parser()
    opts = parser.parse_args(args)
    single = ('tentacle', 'path', 'frame', 'steps', 'playback_step', 'max_field',
              'max_total_field', 'max_field_change', 'max_neighbour_angle')
    if opts.scene and any(getattr(opts, k) is not None for k in single):
        parser.error('--scene takes every setting from the scene file: give it alone, or '
                     '--tentacle and --path with the limits as options')
    if not opts.scene and not (opts.tentacle and opts.path):
        parser.error('give --scene FILE, or --tentacle FILE and --path FILE')
    result = None
    try:
        # Imported here, where Ctrl-C is handled: numpy, scipy, numba and matplotlib take
        # most of the first second.
        from tentacle_planner.planner import plan_scene
        from tentacle_planner.schedule_writer import OUTPUTS
        problem = output_problem(opts.out, OUTPUTS)
        if problem:
            _say(f'--out {problem}')
            return 2
        scene = _scene(opts)
        result = plan_scene(scene, seed=opts.seed, starts=opts.starts,
                            iterations=opts.iterations, min_gain=opts.min_gain,
                            tip_driven=opts.baseline == 'tip-driven', robust=opts.robust,
                            progress=_progress,
                            first_stage=opts.first_stage == 'torque-balance')
        return _write(opts.out, result)
    except PlanInputError as exc:
        _say(exc)
        return 2
    except KeyboardInterrupt:
        when = 'before a plan was found' if result is None else 'before the plan was written'
        _say(f'interrupted {when}: nothing written (what {opts.out} held is as it was)')
        return INTERRUPTED


def _write(out, result):
    """Write the outputs and the summary; return the exit code."""
    from tentacle_planner.plan_plot import write_plot
    from tentacle_planner.schedule_writer import summary, write_schedule_file
    written, interrupted = [], result.interrupted
    try:
        written.append(write_schedule_file(out, result))
        written.append(write_plot(out, result))
        print(summary(result))
    except KeyboardInterrupt:
        interrupted = True
    except OSError as exc:  # the folder was checked before planning; it changed since
        _say(f'{out}: cannot write ({exc.strerror}); written: '
             f'{", ".join(map(str, written)) or "nothing"}')
        return 2
    if written:
        print(f'wrote {" and ".join(map(str, written))}')
    if not interrupted:
        return 3 if result.flags else 0
    if not written:
        _say('interrupted while writing the schedule: nothing written')
        return INTERRUPTED
    what = 'the best plan so far' if result.interrupted else 'the plan'
    _say(f'interrupted: wrote {what} to {written[0]}'
         + (' and its picture' if len(written) == 2 else ', not its picture')
         + (' (its flags say what was left out)' if result.interrupted else ''))
    return INTERRUPTED


if __name__ == '__main__':
    sys.exit(main())
