#!/usr/bin/env python3
"""
Build the compiled kernels once (make venv), so that no first solve or plan waits for them.

numba compiles the model's Newton minimisers and the planner's key step on first use and
keeps them in __pycache__: about 30 s on this machine, paid here instead of by the first
tentacle-plan, sim_node or test (and by two processes at once where a plan forks its
workers before any kernel is built).
"""

import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]

import numpy as np  # noqa: E402
from tentacle_model import batch  # noqa: E402
from tentacle_model.chain import Chain  # noqa: E402
from tentacle_model.statics import compile_kernels  # noqa: E402
from tentacle_planner.planner import problem_of  # noqa: E402
from tentacle_planner.scene import load_scene  # noqa: E402


def main():
    """Compile (or load) every kernel: the model's (one by one, in batch), the planner's."""
    t0 = time.perf_counter()
    compile_kernels()
    one = np.ones(1)
    chain = Chain(one, np.ones((1, 3)), np.ones((1, 3)), one, one, np.zeros(3), np.eye(3))
    for dof in (1, 3):   # design studies' equilibria in batch
        batch.solve(chain, np.ones((1, 1, 3)), np.zeros((1, 3)), dof=dof)
    for scene in ('pancreatic_duct', 'ch3_a'):   # 3-DoF and planar joints
        problem = problem_of(load_scene(ROOT / 'config' / 'scenes' / f'{scene}.yaml'))
        problem.residuals(np.full(problem.size, 0.1))
    print(f'compiled kernels ready in {time.perf_counter() - t0:.0f} s')


if __name__ == '__main__':
    main()
