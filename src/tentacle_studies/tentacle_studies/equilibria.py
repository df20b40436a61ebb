"""The equilibria of a study's points, in batch (tentacle_model.batch): their table columns."""

import numpy as np
from tentacle_model import batch
from tentacle_model.model import TentacleModel
from tentacle_studies.study import AXES

COLUMNS = ('tip_x_m', 'tip_y_m', 'tip_z_m', 'converged', 'stable', 'stability')


def solve_points(study, start, stop):
    """
    Return {column: (k,) values} of points start..stop.

    The varied names, then COLUMNS, then the points of interest (poi_K_x_m, ...: on the link
    that holds each arc length, linearly).

    The points are solved in order, each from the one before (the first straight): a chunk
    of a grid is a run along its last name, so a solve is a few Newton steps. A study whose
    model.start is straight solves each from the straight body.
    """
    return solve_at(study, study.points(start, stop))


def solve_at(study, points, warm=None):
    """
    Return solve_points' columns at points {varied name: (k,) values} of the study's names.

    :param warm: each point from the one before (default: as the study's model.start says)
    """
    spec = study.tentacle
    model = TentacleModel(spec, dof=study.dof, sublinks=study.sublinks,
                          gravity_m_s2=study.gravity_m_s2)
    chain = model.chain(study.inserted_m)
    count = len(next(iter(points.values())))
    own = np.array([s.magnetisation_a_per_m / max(np.linalg.norm(s.magnetisation_a_per_m),
                                                  1e-300) for s in spec.segments])
    directions = np.repeat(own[None], count, axis=0)
    fields = np.repeat(study.field_t[None], count, axis=0)
    for name, values in points.items():
        kind, _, which = name.partition('.')
        if kind == 'magnetisation_deg':
            angle = np.radians(values)
            directions[:, int(which)] = np.column_stack([np.cos(angle), np.sin(angle),
                                                         np.zeros(count)])
        else:
            fields[:, AXES[which]] = values
    interest = study.points_of_interest_m
    solved = batch.solve(chain, directions, fields, model.gravity_m_s2, dof=model.dof,
                         tol=model.tol, max_iterations=model.max_iterations,
                         points=bool(interest),
                         warm=study.warm if warm is None else warm)
    tips = solved.tips_m
    out = {**points, 'tip_x_m': tips[:, 0], 'tip_y_m': tips[:, 1], 'tip_z_m': tips[:, 2],
           'converged': solved.converged, 'stable': solved.stable,
           'stability': solved.stability}
    if interest:
        along = np.concatenate([[0.0], np.cumsum(chain.lengths_m)])   # the joints' arc length
        for k, s in enumerate(interest):
            link = min(max(int(np.searchsorted(along, s, side='right')) - 1, 0), chain.size - 1)
            w = (s - along[link]) / chain.lengths_m[link]
            at = (1 - w) * solved.points_m[:, link] + w * solved.points_m[:, link + 1]
            for axis, name in enumerate('xyz'):
                out[f'poi_{k}_{name}_m'] = at[:, axis]
    return out
