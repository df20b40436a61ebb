"""
tentacle-sweep: run a design study file, writing its results table as chunks complete.

    tentacle-sweep STUDY --out DIR [--resume] [--csv] [--chunk N] [--scheduler ADDRESS]
                   [--workers N]

A study computes an equilibrium a point (equilibria.py) or, with compute: plan, a plan a
point (plans.py). DIR/results.parquet holds one row per point (results.py); Ctrl-C keeps
every chunk finished and says how to continue (--resume computes only the chunks missing).
--csv also writes DIR/results.csv once the table is whole; DIR/plot.png shows the tip (a
plan's error) against one varied name, or maps it over two. Chunks run on every local core
(a Dask LocalCluster) for large studies, or on the Dask cluster at --scheduler (default:
Dask's own ``scheduler-address`` setting, e.g. DASK_SCHEDULER_ADDRESS), or here for small
ones, one chunk or one worker: the same results wherever they run (engines.py). Exit 0 when
every point is in the table, 2 on a refused study or folder, 130 on Ctrl-C.
"""

import argparse
import sys
import time

import numpy as np
import pyarrow.csv as pa_csv
from tentacle_studies import engines
from tentacle_studies.plot import least_over_fields, plot_table
from tentacle_studies.results import Results, ResultsError
from tentacle_studies.study import FIELD_POLAR, load_study, StudyError
from tqdm import tqdm

DEFAULT_CHUNK_POINTS = 8000   # points a chunk: a file each, and what Ctrl-C may lose
DEFAULT_PLAN_CHUNK_POINTS = 2   # a plan is about a second: chunks of two share the cores
# Fewer points than this stay in this process unless --workers says otherwise: starting a
# LocalCluster takes about 2 s, and this process solves some 100,000 points a second (5-link
# 3-DoF tentacle; bench/sweep_scale.py).
LOCAL_WORKERS_FROM_POINTS = 200_000
# Plan studies likewise: on this 2-vCPU machine two workers planned 16 plans of ch3_a in
# 4.1-4.5 s against 3.6 s in this process, 6 of the pancreatic duct in 6.9 against 6.6 s.
LOCAL_WORKERS_FROM_PLANS = 64


def build_parser():
    """Return the argument parser."""
    parser = argparse.ArgumentParser(prog='tentacle-sweep', description=__doc__.split('\n')[1])
    parser.add_argument('study', help='the study file (YAML, ../shared/DESIGN.md)')
    parser.add_argument('--out', required=True, help='folder for results.parquet')
    parser.add_argument('--resume', action='store_true',
                        help="continue this study's table in --out: only missing chunks")
    parser.add_argument('--csv', action='store_true', help='also write results.csv')
    parser.add_argument('--chunk', type=int, metavar='N',
                        help=f'points a chunk (default {DEFAULT_CHUNK_POINTS}, '
                             f'{DEFAULT_PLAN_CHUNK_POINTS} for plans; --resume needs the '
                             'same as the first run)')
    parser.add_argument('--scheduler', metavar='ADDRESS',
                        help="a Dask scheduler's address, e.g. tcp://10.0.0.5:8786 (default: "
                             "Dask's scheduler-address setting, else this machine)")
    parser.add_argument('--workers', type=int, metavar='N',
                        help='local worker processes (default: the cores this process may '
                             'use; 1: in this process)')
    return parser


def engine(opts, chunks, points):
    """Return (the engine's context manager, what it is) for chunks of points to compute."""
    address = opts.scheduler
    if address is None:
        import dask   # its config: a lab sets the address once for every study
        address = dask.config.get('scheduler-address', None)
    if address:
        return engines.dask(address), f'on the Dask cluster at {address}'
    workers = min(opts.workers or engines.local_cores(), chunks)
    enough = LOCAL_WORKERS_FROM_PLANS if opts.plan else LOCAL_WORKERS_FROM_POINTS
    if workers <= 1 or (opts.workers is None and points < enough):
        return engines.in_process(), 'in this process'
    return engines.dask(workers=workers), f'on {workers} local worker processes'


def main(args=None):
    """Run the study; return the exit code."""
    opts = build_parser().parse_args(args)
    if (opts.chunk is not None and opts.chunk < 1) or (opts.workers is not None
                                                       and opts.workers < 1):
        print('tentacle-sweep: --chunk and --workers must be at least 1', file=sys.stderr)
        return 2
    try:
        study = load_study(opts.study)
        opts.plan = study.compute == 'plan'
        chunk = opts.chunk or (DEFAULT_PLAN_CHUNK_POINTS if opts.plan else DEFAULT_CHUNK_POINTS)
        results = Results(opts.out, study, chunk, opts.resume)
    except (StudyError, ResultsError) as exc:
        print(f'tentacle-sweep: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:   # the folder cannot be made or written
        print(f'tentacle-sweep: cannot write results in {opts.out}: {exc}', file=sys.stderr)
        return 2
    missing = results.missing()
    bounds = {index: results.bounds(index) for index in missing}
    todo = sum(stop - start for start, stop in bounds.values())
    running, where = engine(opts, len(missing), todo)
    print(f'{study.name}: {study.size} points ({", ".join(study.names)}), {todo} to compute '
          f'in {len(missing)} chunk(s) of up to {results.chunk_points}, {where}', flush=True)
    t0 = time.perf_counter()
    try:
        with running as compute, tqdm(total=todo, unit='pt', desc=study.name,
                                      file=sys.stderr) as bar:
            for index, columns in compute(study, bounds):
                results.write(index, columns)
                bar.update(bounds[index][1] - bounds[index][0])
    except KeyboardInterrupt:
        done = study.size - sum(stop - start for start, stop in
                                map(results.bounds, results.missing()))
        print(f'\ntentacle-sweep: interrupted: {done} of {study.size} points are in '
              f'{results.table_dir}; run again with --resume to compute the rest',
              file=sys.stderr)
        return 130
    seconds = time.perf_counter() - t0
    table = results.table()
    if opts.csv:
        pa_csv.write_csv(table, results.folder / 'results.csv')
    drawn = plot_table(table, study.names, results.folder / 'plot.png',
                       f'{study.name}: {table.num_rows} points')
    if opts.plan:
        flagged = sum(bool(f) for f in table.column('flags').to_pylist())
        outcome = f'{table.num_rows - flagged} plans without flags, {flagged} flagged'
    else:
        outcome = (f"{sum(table.column('converged').to_pylist())} converged, "
                   f"{sum(table.column('stable').to_pylist())} stable")
    print(f'{study.name}: {table.num_rows} points in {results.table_dir} ({todo} computed in '
          f'{seconds:.1f} s, {todo / max(seconds, 1e-9):.1f} a second); {outcome}'
          + (f'; {drawn}' if drawn else ''))
    others = [n for n in study.names if n not in FIELD_POLAR]
    if study.twist and len(others) == 1:
        print(least_stable_value(table, others[0]))
    return 0


def least_stable_value(table, name):
    """Return a line naming the least value of name at which no field twists the tentacle."""
    keys, least = least_over_fields(table, name)
    stable = np.flatnonzero(least > 0)
    if not stable.size:
        return f'no {name} studied keeps the planar shape stable at every field'
    if stable[0] == 0:
        return f'every {name} studied keeps the planar shape stable at every field'
    return (f'the least {name} that keeps the planar shape stable at every field: '
            f'{keys[stable[0]]:g} (least twist stability {least[stable[0]]:.3g} N m/rad^2; '
            f'{keys[stable[0] - 1]:g} twists at some)')


if __name__ == '__main__':
    sys.exit(main())
