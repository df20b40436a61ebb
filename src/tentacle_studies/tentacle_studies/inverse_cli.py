"""
tentacle-inverse: the magnetisation angles that give requested deflections (thesis chapter 2).

    tentacle-inverse STUDY [--table DIR] --deflections-mm D1 D2 ... [--deflections-mm ...]
                     [--method direct|network|lookup]

STUDY is a babble: a grid over the magnets' magnetisation angles, each through a whole turn,
with one point of interest per magnet (config/studies/ch2_babble.yaml). Its table is read
from DIR (tentacle-sweep STUDY --out DIR) or solved here. A shape is one deflection a point
of interest, mm, along the base's normal from the straight body. Methods (figures:
bench/ch2_inverse.py): direct (default) optimises the angles in the forward model from the
table's nearest shape; network is the thesis' learned inverse (six layers of 20, trained
here on the table's points left after its redundancy removal, some seconds); lookup takes
the table's nearest shape. Every answer is checked in the forward model: the deflections it
gives, the thesis' error (summed |achieved - requested| over summed |requested|) and
whether it is stable. Exit 0 with every answer printed, 2 on refused input.
"""

import argparse
import sys
import time

import numpy as np
from tentacle_studies import equilibria, inverse
from tentacle_studies.results import read_results, ResultsError
from tentacle_studies.study import load_study, StudyError

SOLVED_HERE_AT_MOST = 200_000   # points of a babble solved here without --table
REACHED = 0.01                  # an error under 1% of the request: the shape is made


def build_parser():
    """Return the argument parser."""
    parser = argparse.ArgumentParser(prog='tentacle-inverse',
                                     description=__doc__.split('\n')[1])
    parser.add_argument('study', help='a babble study file (YAML)')
    parser.add_argument('--table', metavar='DIR',
                        help="the study's finished tentacle-sweep --out folder (default: "
                             f'solve it here, up to {SOLVED_HERE_AT_MOST} points)')
    parser.add_argument('--deflections-mm', type=float, nargs='+', action='append',
                        required=True, metavar='D',
                        help='one shape: a deflection a point of interest, mm (repeat the '
                             'option for more shapes)')
    parser.add_argument('--method', choices=('direct', 'network', 'lookup'), default='direct')
    return parser


def main(args=None):
    """Answer every requested shape; return the exit code."""
    opts = build_parser().parse_args(args)
    try:
        study = load_study(opts.study)
        requested = _shapes(opts.deflections_mm, len(study.points_of_interest_m))
        columns = _table(study, opts.table)
        grid = inverse.babble(study, columns)
    except (StudyError, ResultsError, inverse.BabbleError, ValueError) as exc:
        print(f'tentacle-inverse: {exc}', file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    if opts.method == 'network':
        mask, _ = inverse.redundancy_mask(grid)
        network = inverse.Inverse().fit(*reversed(grid.points(mask)))
        print(f'{study.name}: the thesis network trained on {mask.sum()} of {mask.size} '
              f'points in {time.perf_counter() - t0:.1f} s')
        answers = network.angles_rad(requested)
    else:
        nearest = grid.nearest(requested)
        answers = nearest if opts.method == 'lookup' else np.array(
            [inverse.direct(study, grid.names, want, start).angles_rad
             for want, start in zip(requested, nearest)])
    achieved, stable = inverse.forward(study, grid.names, answers)
    print(f'{study.name}: {opts.method}, {len(requested)} shape(s) in '
          f'{time.perf_counter() - t0:.2f} s; points of interest at '
          + ', '.join(f'{1e3 * s:g}' for s in study.points_of_interest_m) + ' mm')
    missed = ('out of reach: the nearest shape found' if opts.method == 'direct' else
              'not reached: --method direct finds the nearest shape')
    for want, angle, got, ok in zip(requested, answers, achieved, stable):
        error = inverse.deflection_error(got, want)
        print('  requested ' + _mm(want) + ' -> '
              + ', '.join(f'{name} {a:.1f}' for name, a in
                          zip(grid.names, np.degrees(angle) % 360.0))
              + f' deg -> achieved {_mm(got)}: error {100 * error:.1f}%'
              + ('' if ok else ', NOT STABLE')
              + ('' if error < REACHED else f' ({missed})'))
    return 0


def _shapes(values, points):
    """Return (N, points) requested deflections, m, from --deflections-mm lists."""
    for shape in values:
        if len(shape) != points:
            raise ValueError(f'--deflections-mm {" ".join(map(str, shape))}: one deflection '
                             f'a point of interest, {points} of them')
    shapes = np.array(values, dtype=float) * 1e-3
    if not np.all(np.isfinite(shapes)) or np.all(shapes == 0.0, axis=1).any():
        raise ValueError('--deflections-mm: finite, and not all zero (the error is relative)')
    return shapes


def _table(study, folder):
    """Return the study's table: read from folder, or solved here when small."""
    if folder is not None:
        return read_results(folder, study)
    if study.size > SOLVED_HERE_AT_MOST:
        raise ValueError(f'{study.name}: {study.size} points: solve them first '
                         '(tentacle-sweep STUDY --out DIR) and pass --table DIR')
    return equilibria.solve_points(study, 0, study.size)


def _mm(deflections_m):
    return '[' + ' '.join(f'{1e3 * d:.2f}' for d in deflections_m) + '] mm'


if __name__ == '__main__':
    sys.exit(main())
