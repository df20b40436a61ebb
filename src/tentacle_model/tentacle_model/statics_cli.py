"""
tentacle-statics: the equilibrium of a tentacle in a uniform field, for what-ifs.

    tentacle-statics --tentacle config/tentacles/cantilever.yaml --field 0 0.005 0 --json

Prints the centreline, the tip position and heading, the stability (smallest Hessian
eigenvalue) and whether the solve converged. Exit code 0 when converged, 3 when not (the
result is still printed), 2 for bad input, including a problem beyond the size limits
(statics.MAX_LINKS, statics.MAX_ESTIMATED_BYTES, tentacle_spec.MAX_FILE_BYTES). With
``--linear`` an answer with a link turned more than statics.SMALL_ANGLE_LIMIT_RAD from the
insertion direction is outside the small-angle model's range: printed, said so, not
converged, exit code 3.
"""

import argparse
import json
import re
import sys

import numpy as np
from tentacle_model.chain import discretise
from tentacle_model.statics import small_angle_violation, solve
from tentacle_model.tentacle_spec import load_tentacle, SpecError

# Any float, as float() reads it. argparse takes an argument for an option unless it matches
# its negative-number pattern, which (Python 3.11) has no exponent: '--field 0 -5e-3 0' would
# be an error. No option here looks like a number, so nothing is lost.
NEGATIVE_NUMBER = re.compile(r'^-(?:(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?|inf(?:inity)?|nan)$',
                             re.IGNORECASE)


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='tentacle-statics',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('--tentacle', required=True, help='tentacle YAML file')
    parser.add_argument('--field', nargs=3, type=float, required=True,
                        metavar=('BX', 'BY', 'BZ'), help='uniform field, tesla')
    parser.add_argument('--inserted', type=float, default=None, metavar='METRES',
                        help='length pushed past the base (default: all)')
    parser.add_argument('--sublinks', type=int, default=20, help='links per segment')
    parser.add_argument('--backbone', type=float, default=0.0, metavar='METRES',
                        help='how far the stiffening backbone reaches past the base '
                             '(default 0: retracted)')
    parser.add_argument('--dof', type=int, choices=(1, 3), default=1,
                        help='joint degrees of freedom: 1 planar, 3 bend-bend-twist')
    parser.add_argument('--gravity', nargs=3, type=float, default=(0.0, 0.0, 0.0),
                        metavar=('GX', 'GY', 'GZ'), help='gravity, m/s^2 (default none)')
    parser.add_argument('--dipoles', action='store_true',
                        help='magnet-to-magnet (dipole-dipole) interaction between segments')
    parser.add_argument('--linear', action='store_true',
                        help='small-angle (linearised) model: one linear solve')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser._negative_number_matcher = NEGATIVE_NUMBER
    return parser


def main(args=None):
    """Solve and print; return the exit code."""
    opts = build_parser().parse_args(args)
    try:
        spec = load_tentacle(opts.tentacle)
        chain = discretise(spec, opts.inserted, opts.sublinks, opts.backbone)
        eq = solve(chain, opts.field, opts.gravity, dof=opts.dof, linear=opts.linear,
                   dipoles=opts.dipoles)
    except (SpecError, ValueError) as exc:
        print(f'tentacle-statics: {exc}', file=sys.stderr)
        return 2
    converged, reason = eq.converged, eq.reason
    outside = small_angle_violation(eq, float(chain.lengths_m.sum())) if opts.linear else None
    if outside and converged:  # the linear solve is exact, the model no longer is
        converged, reason = False, outside
    result = {
        'tentacle': spec.name, 'field_t': list(opts.field), 'inserted_m': float(
            chain.lengths_m.sum()), 'links': chain.size, 'dof': opts.dof,
        'dipoles': opts.dipoles, 'linear': opts.linear, 'backbone_m': opts.backbone,
        'tip': eq.tip_m.tolist(), 'heading': eq.heading.tolist(),
        'converged': converged, 'reason': reason, 'iterations': eq.iterations,
        'residual': eq.residual,
        'stability': eq.stability if np.isfinite(eq.stability) else None,
        'energy_j': eq.energy_j, 'points': eq.points_m.tolist()}
    if opts.json:
        print(json.dumps(result))
    else:
        print(f'{spec.name}: {chain.size} links, {result["inserted_m"] * 1e3:.3f} mm inserted, '
              f'field {np.round(np.array(opts.field) * 1e3, 4).tolist()} mT')
        print('centreline (mm):')
        for p in eq.points_m:
            print(f'  {p[0] * 1e3:9.4f} {p[1] * 1e3:9.4f} {p[2] * 1e3:9.4f}')
        print(f'tip (mm): {np.round(eq.tip_m * 1e3, 4).tolist()}   heading: '
              f'{np.round(eq.heading, 4).tolist()}')
        state = 'NOT VALID' if outside else 'converged' if converged else 'NOT CONVERGED'
        print(f'{state}: {reason} ({eq.iterations} iterations, residual {eq.residual:.2e})')
        print(f'stability (smallest Hessian eigenvalue): {eq.stability:.4g} N m/rad^2'
              + ('  UNSTABLE' if eq.stability < 0 else ''))
    return 0 if converged else 3


if __name__ == '__main__':
    sys.exit(main())
