"""
Fit the actuation matrix A and field offset b0 (B = A I + b0) from measurements.

Input: a CSV with a header row and one row per measurement, SI units:
``current_x_a,current_y_a,current_z_a,field_x_t,field_y_t,field_z_t`` (a gaussmeter at the
coil centre, supplies at the listed currents), in any order, each once; other columns are
ignored. UTF-8, with or without Excel's byte-order mark ("CSV UTF-8"). The fit is linear
least squares; its residual says how well a uniform affine model explains the data. A fit
whose matrix is singular or ill-conditioned (condition number above ``--max-condition``,
100 by default) is refused and never written: the node inverts A, and such an A would ask
for currents the measurements do not support.

Command line (``scripts/calibrate_coils``; needs no ROS workspace sourced)::

    calibrate_coils measurements.csv [--write config/coils.yaml] [--no-offset]
                    [--max-condition 100]

Exit status: 0 fitted (and written), 2 bad input (the file, line or column named).
"""

import argparse
import csv
from dataclasses import dataclass
import io
import sys

import numpy as np
from tentacle_coils.errors import ConfigError
from tentacle_common.yaml_files import FileRefused, read_text, set_flow_list, write_text

COLUMNS = ('current_x_a', 'current_y_a', 'current_z_a', 'field_x_t', 'field_y_t', 'field_z_t')
NODE_NAME = 'coils_node'  # the params file's section the fit goes into
MAX_CSV_BYTES = 16 << 20  # about 200 000 measurements; a larger file is not a calibration
# A three-axis coil's axes differ in strength by a few times (the reference rig: 2.0); past
# this, an axis was barely measured or two axes point the same way.
MAX_CONDITION = 100.0


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

    :raises ConfigError: unreadable, not a regular file, not UTF-8; a needed column missing
        or given twice; a row with more or fewer fields than the header; a non-numeric or
        non-finite value (file, line and column named); or no rows
    """
    try:
        text = read_text(path, MAX_CSV_BYTES, encoding='utf-8-sig')
    except OSError as exc:
        raise ConfigError(f'{path}: {exc.strerror or exc}') from None
    except FileRefused as exc:
        raise ConfigError(f'{path}: {exc}'
                          + ('; save it as "CSV UTF-8"' if 'UTF-8' in str(exc) else '')) \
            from None
    reader = csv.reader(io.StringIO(text, newline=''))
    try:
        header = [name.strip() for name in next(reader, [])]
        missing = [c for c in COLUMNS if c not in header]
        if missing:
            raise ConfigError(f'{path}: missing column(s) {", ".join(missing)}; '
                              f'expected {",".join(COLUMNS)}')
        for column in COLUMNS:
            at = [str(k + 1) for k, name in enumerate(header) if name == column]
            if len(at) > 1:  # csv.DictReader would silently keep the last one
                raise ConfigError(f'{path}: column {column} given {len(at)} times (columns '
                                  f'{", ".join(at)}); each must be given once')
        index = [header.index(c) for c in COLUMNS]
        rows = []
        for fields in reader:
            if not fields or all(not f.strip() for f in fields):
                continue  # a blank line
            if len(fields) != len(header):
                raise ConfigError(f'{path}:{reader.line_num}: {len(fields)} fields where the '
                                  f'header has {len(header)}')
            values = []
            for column, k in zip(COLUMNS, index):
                try:
                    value = float(fields[k])
                except ValueError:
                    raise ConfigError(f'{path}:{reader.line_num}: not a number in column '
                                      f'{column}: {fields[k]!r}') from None
                if not np.isfinite(value):
                    raise ConfigError(f'{path}:{reader.line_num}: value not finite in column '
                                      f'{column}: {fields[k]!r}')
                values.append(value)
            rows.append(values)
    except csv.Error as exc:
        raise ConfigError(f'{path}:{reader.line_num}: not CSV: {exc}') from None
    if not rows:
        raise ConfigError(f'{path}: no measurements')
    data = np.array(rows)
    return data[:, :3], data[:, 3:]


def fit(currents_a, fields_t, with_offset=True, max_condition=MAX_CONDITION):
    """
    Fit B = A I (+ b0) by least squares.

    :param currents_a: (n, 3) currents, ampere
    :param fields_t: (n, 3) measured fields, tesla
    :param max_condition: largest condition number of A accepted (2-norm)
    :raises ConfigError: too few samples, currents that do not excite all three axes, or a
        fitted A that is singular or has a condition number above max_condition
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
    matrix = solution[:3].T
    condition = np.linalg.cond(matrix)
    if not condition <= max_condition:  # also inf and nan: a singular A
        norms_mt_per_a = np.linalg.norm(matrix, axis=1) * 1e3
        rows = ', '.join(f'{a} {n:.4g}' for a, n in zip('xyz', norms_mt_per_a))
        raise ConfigError(f'the fitted matrix is singular or ill-conditioned: condition number '
                          f'{condition:.3g}, limit {max_condition:g} (row norms, mT/A: {rows}); '
                          "check that every field column holds its own axis's measurements")
    residual = fields_t - design @ solution
    return Fit(matrix_t_per_a=matrix,
               offset_t=solution[3] if with_offset else np.zeros(3),
               residual_rms_t=np.sqrt(np.mean(residual ** 2, axis=0)),
               residual_max_t=float(np.max(np.abs(residual))), samples=len(design))


def write_into_config(path, result):
    """
    Put actuation_matrix and field_offset into a coils params file's coils_node section.

    Only those keys' lines change; comments and every other line stay (the edit is checked
    by parsing the result again). The file is replaced in one step.

    :raises ConfigError: the file is unreadable, not a regular file, has no coils_node
        section, or a layout that cannot be edited safely; nothing is written then
    """
    try:
        text = read_text(path)
    except OSError as exc:
        raise ConfigError(f'{path}: cannot be read: {exc.strerror or exc}') from None
    except FileRefused as exc:
        raise ConfigError(f'{path}: {exc}; nothing written') from None
    try:
        if f'\n{NODE_NAME}:' not in '\n' + text and f'\n/{NODE_NAME}:' not in '\n' + text:
            raise ConfigError(f'{path}: no {NODE_NAME} section (is this the coils params '
                              'file?)')
        text = set_flow_list(text, NODE_NAME, 'actuation_matrix',
                             result.matrix_t_per_a.ravel(), per_line=3)
        text = set_flow_list(text, NODE_NAME, 'field_offset', result.offset_t)
        write_text(path, text)
    except OSError as exc:
        raise ConfigError(f'{path}: cannot be written: {exc.strerror or exc}') from None
    except FileRefused as exc:
        raise ConfigError(f'{path}: {exc}; nothing written') from None


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
    parser.add_argument('--max-condition', type=float, default=MAX_CONDITION,
                        help='refuse a fitted A whose condition number is larger (default '
                        '%(default)g)')
    opts = parser.parse_args(args)
    if not opts.max_condition >= 1.0:  # no matrix has a condition number below 1
        parser.error(f'--max-condition {opts.max_condition:g}: must be at least 1')
    try:
        measured = read_measurements(opts.csv)
        try:
            result = fit(*measured, with_offset=not opts.no_offset,
                         max_condition=opts.max_condition)
        except ConfigError as exc:
            raise ConfigError(f'{opts.csv}: {exc}') from None
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
