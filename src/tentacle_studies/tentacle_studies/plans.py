"""
The plans of a plan study's points (compute: plan): their table columns.

Each point is its scene with the tentacle the point's names make (equilibria.varied_tentacle)
planned by the planner as tentacle-plan plans it (tentacle_planner.planner.plan_scene, the
point's seed), without the dense playback: DESIGN.md's columns, the shape error planned and
re-checked in the finer model, and the plan's flags. A plan takes 0.2 to 1.1 s here, so a
chunk is 2 points; one process a plan (the engines run chunks side by side).
"""

from dataclasses import replace

import numpy as np
from tentacle_planner.planner import plan_scene, shape_rms
from tentacle_studies.equilibria import varied_tentacle

COLUMNS = ('shape_rms_m', 'recheck_rms_m', 'flags')


def plan_points(study, start, stop):
    """
    Return {column: (k,) values} of points start..stop: the varied names, then COLUMNS.

    :raises KeyboardInterrupt: Ctrl-C in a plan (its point is not a result: the chunk is
        computed again on --resume)
    """
    points = study.points(start, stop)
    count = len(next(iter(points.values())))
    columns = {name: [] for name in COLUMNS}
    for p in range(count):
        row = {name: values[p] for name, values in points.items()}
        scene = replace(study.scene, tentacle=varied_tentacle(
            study.scene.tentacle, {n: v for n, v in row.items() if n != 'seed'}),
            playback_step_m=None)
        result = plan_scene(scene, seed=int(row.get('seed', 0)), workers=1)
        if result.interrupted:
            raise KeyboardInterrupt
        columns['shape_rms_m'].append(shape_rms(scene, result.plan.steps))
        columns['recheck_rms_m'].append(rechecked_m(result))
        columns['flags'].append('; '.join(result.flags))
    return {**points, 'shape_rms_m': np.array(columns['shape_rms_m']),
            'recheck_rms_m': np.array(columns['recheck_rms_m']),
            'flags': np.array(columns['flags'], dtype=object)}


def rechecked_m(result):
    """Return the plan's shape RMS re-checked in the finer model, m (the worst re-check)."""
    finer = [rms for what, rms in result.verification if what.startswith('higher fidelity')]
    return finer[0] if finer else max((rms for _, rms in result.verification),
                                      default=float('nan'))
