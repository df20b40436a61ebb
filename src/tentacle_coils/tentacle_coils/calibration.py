"""
Fit the actuation matrix A and field offset b0 (B = A I + b0) from measurements.

Input: a CSV with a header row and one row per measurement, SI units:
``current_x_a,current_y_a,current_z_a,field_x_t,field_y_t,field_z_t`` (a gaussmeter at the
coil centre, supplies at the listed currents). The fit is linear least squares; its
residual says how well a uniform affine model explains the data.

Command line (``scripts/calibrate_coils``)::

    calibrate_coils measurements.csv [--write config/coils.yaml] [--no-offset]
"""

import argparse
import csv
from dataclasses import dataclass
import re
import sys

import numpy as np

from tentacle_coils.errors import ConfigError

COLUMNS = ('current_x_a', 'current_y_a', 'current_z_a', 'field_x_t', 'field_y_t', 'field_z_t')


@dataclass(frozen=True)
class Fit:
    """A fitted calibration and how well it explains the data."""

    matrix_t_per_a: np.ndarray   # (3, 3)
    offset_t: np.ndarray         # (3,)
    residual_rms_t: np.ndarray   # (3,) per field axis
    residual_max_t: float
    samples: int


def read_measurements(path):
    """
    Return (currents (n, 3) in A, fields (n, 3) in T) from a CSV.

    :raises ConfigError: missing columns, a non-numeric or non-finite value (file and line
        named), or no rows
    """
    try:
        with open(path, newline='', encoding='utf-8') as handle:
            reader = csv.DictReader(handle)
            missing = [c for c in COLUMNS if c not in (reader.fieldnames or [])]
            if missing:
                raise ConfigError(f'{path}: missing column(s) {", ".join(missing)}; '
                                  f'expected {",".join(COLUMNS)}')
            rows = []
            for row in reader:
                try:
                    values = [float(row[c]) for c in COLUMNS]
                except (TypeError, ValueError):
                    raise ConfigError(f'{path}:{reader.line_num}: not a number in '
                                      f'{[row.get(c) for c in COLUMNS]}') from None
                if not np.all(np.isfinite(values)):
                    raise ConfigError(f'{path}:{reader.line_num}: value not finite')
                rows.append(values)
    except OSError as exc:
        raise ConfigError(f'{path}: {exc.strerror}') from None
    if not rows:
        raise ConfigError(f'{path}: no measurements')
    data = np.array(rows)
    return data[:, :3], data[:, 3:]


def fit(currents_a, fields_t, with_offset=True):
    """
    Fit B = A I (+ b0) by least squares.

    :param currents_a: (n, 3) currents, ampere
    :param fields_t: (n, 3) measured fields, tesla
    :raises ConfigError: too few samples, or currents that do not excite all three axes
    """
    currents_a = np.asarray(currents_a, dtype=float)
    fields_t = np.asarray(fields_t, dtype=float)
    design = np.hstack([currents_a, np.ones((len(currents_a), 1))]) if with_offset \
        else currents_a
    unknowns = design.shape[1]
    if len(design) < unknowns:
        raise ConfigError(f'{len(design)} measurements cannot fit {unknowns} unknowns per axis')
    if np.linalg.matrix_rank(design) < unknowns:
        raise ConfigError('the currents do not excite every axis independently '
                          '(the measurements are rank deficient)')
    solution, *_ = np.linalg.lstsq(design, fields_t, rcond=None)
    residual = fields_t - design @ solution
    return Fit(matrix_t_per_a=solution[:3].T,
               offset_t=solution[3] if with_offset else np.zeros(3),
               residual_rms_t=np.sqrt(np.mean(residual ** 2, axis=0)),
               residual_max_t=float(np.max(np.abs(residual))), samples=len(design))


def _flow(values, indent):
    rows = [', '.join(f'{v:.6e}' for v in values[i:i + 3]) for i in range(0, len(values), 3)]
    return '[' + (',\n' + ' ' * indent).join(rows) + ']'


def write_into_config(path, result):
    """
    Replace actuation_matrix and field_offset in a coils params file, keeping comments.

    :raises ConfigError: the file lacks either key
    """
    with open(path, encoding='utf-8') as handle:
        text = handle.read()
    for key, values in (('actuation_matrix', result.matrix_t_per_a.ravel()),
                        ('field_offset', result.offset_t)):
        pattern = re.compile(rf'^(\s*{key}:\s*)\[[^\]]*\]', re.MULTILINE)
        match = pattern.search(text)
        if not match:
            raise ConfigError(f'{path}: no "{key}: [...]" entry to replace')
        indent = len(match.group(1))
        text = text[:match.start()] + match.group(1) + _flow(values, indent) + \
            text[match.end():]
    with open(path, 'w', encoding='utf-8') as handle:
        handle.write(text)


def report(result):
    """Return the fit as text for the operator."""
    diag = np.diag(result.matrix_t_per_a) * 1e3
    lines = [f'fit of {result.samples} measurements: B = A I + b0',
             'A (mT/A):'] + ['  ' + '  '.join(f'{v:9.5f}' for v in row)
                             for row in result.matrix_t_per_a * 1e3]
    lines += [f'b0 (mT): {np.round(result.offset_t * 1e3, 5).tolist()}',
              f'diagonal (mT/A): x {diag[0]:.4f}, y {diag[1]:.4f}, z {diag[2]:.4f}',
              'residual RMS (uT): ' + ', '.join(
                  f'{a} {r * 1e6:.2f}' for a, r in zip('xyz', result.residual_rms_t)),
              f'residual max (uT): {result.residual_max_t * 1e6:.2f}']
    return '\n'.join(lines)


def main(args=None):
    """Fit a calibration CSV, print the fit, optionally write it into a params file."""
    parser = argparse.ArgumentParser(prog='calibrate_coils',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('csv', help='measurements: ' + ','.join(COLUMNS))
    parser.add_argument('--write', metavar='PARAMS_YAML',
                        help='put the fit into this coils params file (e.g. config/coils.yaml)')
    parser.add_argument('--no-offset', action='store_true', help='fit B = A I (b0 = 0)')
    opts = parser.parse_args(args)
    try:
        result = fit(*read_measurements(opts.csv), with_offset=not opts.no_offset)
        print(report(result))
        if opts.write:
            write_into_config(opts.write, result)
            print(f'written into {opts.write}')
    except ConfigError as exc:
        print(f'calibrate_coils: {exc}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
