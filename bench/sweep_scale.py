#!/usr/bin/env python3
"""
Benchmark: design studies' equilibria per second, in batch and one by one, here and on Dask.

First one core: the chapter 5 braided tentacle (5 links; 3-DoF and planar joints) over a
grid of its two distal magnets' angles (24 x 24, repeated), tentacle_model.batch against
one TentacleModel.solve a point, side by side. Then tentacle-sweep's engines on a study of
518,400 points (100 fields x 72 x 72 angles, 3-DoF): in this process, on a LocalCluster of
2 single-threaded workers (its start included: it is what a run pays) and on a Dask cluster
of 2 workers already running (a scheduler and 2 worker processes, as a lab's, reached by
--scheduler), at 2000, 8000 and 32000 points a chunk; and a plan study (16 seeds of thesis
scene ch3_a, a plan each) at 1, 2, 4 and 8 points a chunk.

Run: .venv/bin/python bench/sweep_scale.py
"""

import pathlib
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]

import numpy as np  # noqa: E402
from tentacle_model import batch  # noqa: E402
from tentacle_model.model import TentacleModel  # noqa: E402
from tentacle_model.tentacle_spec import load_tentacle  # noqa: E402
from tentacle_studies import engines as studies_engines, sweep_cli  # noqa: E402

TENTACLE = ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml'
STUDY = f"""name: sweep_scale
tentacle: {TENTACLE}
field_t: [0.0, 0.005, 0.0]
model: {{dof: 3, sublinks: 1}}
vary:
  field_t.y: {{from: 0.001, to: 0.010, count: 100}}
  magnetisation_deg.3: {{from: 0, to: 355, count: 72}}
  magnetisation_deg.4: {{from: 0, to: 355, count: 72}}
"""

PLAN_STUDY = f"""name: plan_scale
compute: plan
scene: {ROOT / 'config' / 'scenes' / 'ch3_a.yaml'}
vary:
  seed: [{', '.join(map(str, range(16)))}]
"""


def grid_points(spec, repeats):
    """Return (directions (P, segments, 3), fields (P, 3)) of the 24 x 24 grid, repeated."""
    angles = np.radians(np.arange(0, 360, 15))
    distal, before = (g.ravel() for g in np.meshgrid(angles, angles, indexing='ij'))
    directions = np.array([s.magnetisation_a_per_m / np.linalg.norm(s.magnetisation_a_per_m)
                           for s in spec.segments])
    directions = np.repeat(directions[None], distal.size, axis=0)
    for segment, angle in ((-1, distal), (-2, before)):
        directions[:, segment] = np.column_stack([np.cos(angle), np.sin(angle),
                                                  np.zeros(angle.size)])
    directions = np.tile(directions, (repeats, 1, 1))
    return directions, np.tile([0.0, 0.005, 0.0], (len(directions), 1))


def one_core():
    """Print equilibria per second on one core: in batch and one solve a point."""
    spec = load_tentacle(TENTACLE)
    print('one core, braided tentacle (5 links), 24 x 24 grid of two magnets in 5 mT:')
    for dof in (3, 1):
        model = TentacleModel(spec, dof=dof)
        chain = model.chain(spec.length_m)
        directions, fields = grid_points(spec, 20)
        batch.solve(chain, directions[:10], fields[:10], dof=dof)   # the kernels, loaded
        t0 = time.perf_counter()
        solved = batch.solve(chain, directions, fields, dof=dof)
        in_batch = len(fields) / (time.perf_counter() - t0)
        magnitudes = np.linalg.norm(chain.moments_a_m2, axis=1)
        t0, count = time.perf_counter(), 1000
        for p in range(count):
            model.solve(spec.length_m, fields[p], None,
                        magnitudes[:, None] * directions[p][chain.segment_index])
        each = count / (time.perf_counter() - t0)
        print(f'  {"3-DoF" if dof == 3 else "planar"}: in batch {in_batch:9.0f} a second '
              f'({solved.iterations.mean():.1f} Newton steps a point, warm), one solve a '
              f'point {each:7.0f} a second ({in_batch / each:.1f}x)')


def engines(text, points, chunks, what):
    """
    Print tentacle-sweep's points per second by chunk size, here and on two Dask clusters.

    On 2 local workers (a LocalCluster the run starts) and on a Dask cluster of 2 workers
    already running (a scheduler and worker processes, as a lab's: --scheduler).
    """
    print(f'tentacle-sweep, {points:,} {what}, wall time of the run:')
    with tempfile.TemporaryDirectory() as tmp, \
            studies_engines.cluster_processes(tmp, workers=2) as address:
        study = pathlib.Path(tmp) / 'study.yaml'
        study.write_text(text)
        for chunk in chunks:
            for k, (where, argv) in enumerate((('this process', ['--workers', '1']),
                                               ('2 local workers', ['--workers', '2']),
                                               ('Dask cluster of 2', ['--scheduler', address]))):
                out = pathlib.Path(tmp) / f'out_{chunk}_{k}'
                t0 = time.perf_counter()
                code = sweep_cli.main([str(study), '--out', str(out), '--chunk', str(chunk),
                                       *argv])
                seconds = time.perf_counter() - t0
                assert code == 0
                print(f'  {chunk:5d} points a chunk, {where:17s}: {seconds:5.2f} s, '
                      f'{points / seconds:9.2f} points a second', flush=True)


if __name__ == '__main__':
    one_core()
    engines(STUDY, 518_400, (2000, 8000, 32000), 'equilibrium points (3-DoF)')
    engines(PLAN_STUDY, 16, (1, 2, 4, 8), 'plan points (thesis scene ch3_a, 16 seeds)')
