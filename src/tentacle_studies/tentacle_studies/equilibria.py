"""The equilibria of a study's points, in batch (tentacle_model.batch): their table columns."""

from dataclasses import replace
import math

import numpy as np
from tentacle_model import batch
from tentacle_model.model import TentacleModel
from tentacle_model.tentacle_spec import MU0, reinforced
from tentacle_studies.study import AXES, FIBRE_NAMES, STRUCTURAL

COLUMNS = ('tip_x_m', 'tip_y_m', 'tip_z_m', 'converged', 'stable', 'stability')


def solve_points(study, start, stop):
    """
    Return {column: (k,) values} of points start..stop.

    The varied names, then COLUMNS, then twist_stability (model.twist_stability), then the
    points of interest (poi_K_x_m, ...: on the link that holds each arc length, linearly).

    The points are solved in order, each from the one before (the first straight): a chunk
    of a grid is a run along its last name, so a solve is a few Newton steps. A study whose
    model.start is straight solves each from the straight body.
    """
    return solve_at(study, study.points(start, stop))


def solve_at(study, points, warm=None):
    """
    Return solve_points' columns at points {varied name: (k,) values} of the study's names.

    Points with the same tentacle (study.STRUCTURAL names alike) in a row are solved as one
    batch; a point whose tentacle differs from the one before starts straight.

    :param warm: each point from the one before (default: as the study's model.start says)
    """
    count = len(next(iter(points.values())))
    directions, fields = _directions_and_fields(study, points, count)
    interest = study.points_of_interest_m
    names = [*COLUMNS, *(['twist_stability'] if study.twist else []),
             *(f'poi_{k}_{a}_m' for k in range(len(interest)) for a in 'xyz')]
    columns = {name: [] for name in names}
    for start, stop, tentacle, inserted_m, backbone_m in _tentacles(study, points, count):
        model = TentacleModel(tentacle, dof=study.dof, sublinks=study.sublinks,
                              gravity_m_s2=study.gravity_m_s2, backbone_m=backbone_m)
        chain = model.chain(inserted_m)
        solved = batch.solve(chain, directions[start:stop], fields[start:stop],
                             model.gravity_m_s2, dof=model.dof, tol=model.tol,
                             max_iterations=model.max_iterations, points=bool(interest),
                             warm=study.warm if warm is None else warm, twist=study.twist)
        for name, values in zip(COLUMNS, (*solved.tips_m.T, solved.converged, solved.stable,
                                          solved.stability)):
            columns[name].append(values)
        if study.twist:
            columns['twist_stability'].append(solved.twist_stability)
        along = np.concatenate([[0.0], np.cumsum(chain.lengths_m)])   # the joints' arc length
        for k, s in enumerate(interest):
            link = min(max(int(np.searchsorted(along, s, side='right')) - 1, 0), chain.size - 1)
            w = (s - along[link]) / chain.lengths_m[link]
            at = (1 - w) * solved.points_m[:, link] + w * solved.points_m[:, link + 1]
            for axis, name in enumerate('xyz'):
                columns[f'poi_{k}_{name}_m'].append(at[:, axis])
    return {**points, **{name: np.concatenate(parts) for name, parts in columns.items()}}


def _directions_and_fields(study, points, count):
    """Return each point's magnetisation directions (count, segments, 3) and field (count, 3)."""
    own = np.array([s.magnetisation_a_per_m / max(np.linalg.norm(s.magnetisation_a_per_m),
                                                  1e-300) for s in study.tentacle.segments])
    directions = np.repeat(own[None], count, axis=0)
    fields = np.repeat(study.field_t[None], count, axis=0)
    for name, values in points.items():
        kind, _, which = name.partition('.')
        if kind == 'magnetisation_deg':
            angle = np.radians(values)
            directions[:, int(which)] = np.column_stack([np.cos(angle), np.sin(angle),
                                                         np.zeros(count)])
        elif kind == 'field_t':
            fields[:, AXES[which]] = values
    if 'field_angle_deg' in points:   # in the base's plane, from its direction to its normal
        angle = np.radians(points['field_angle_deg'])
        plane = study.tentacle.base_rotation[:, :2]
        fields = points['field_strength_t'][:, None] * (
            np.column_stack([np.cos(angle), np.sin(angle)]) @ plane.T)
    return directions, fields


def _tentacles(study, points, count):
    """Yield (start, stop, TentacleSpec, inserted_m, backbone_m) of each run of points alike."""
    names = [n for n in points if n.partition('.')[0] in STRUCTURAL]
    if not names:
        yield 0, count, study.tentacle, study.inserted_m, 0.0
        return
    values = np.column_stack([points[n] for n in names])
    edges = [0, *(np.flatnonzero(np.any(values[1:] != values[:-1], axis=1)) + 1), count]
    for start, stop in zip(edges[:-1], edges[1:]):
        row = dict(zip(names, values[start]))
        yield (start, stop, varied_tentacle(study.tentacle, row),
               row.get('inserted_m', study.inserted_m), row.get('backbone_m', 0.0))


def varied_tentacle(spec, row):
    """
    Return spec with its segments as a row {structural name: value} of a study makes them.

    A reinforced segment's youngs_modulus_pa is its matrix's and its fibres' names change
    its fibres: its pseudo-moduli are derived again; bend_modulus_pa and twist_modulus_pa
    then set pseudo-moduli outright.
    """
    segments = list(spec.segments)
    for k, segment in enumerate(segments):
        fibres, matrix = segment.reinforcement, segment.matrix_modulus_pa
        changed = False
        for name, value in row.items():
            kind, _, which = name.partition('.')
            if kind in FIBRE_NAMES and fibres is not None and which in ('', str(k)):
                key = {'fibre_angle_deg': 'angle_rad'}.get(kind, kind)
                fibres = replace(fibres, **{key: math.radians(value)
                                            if kind == 'fibre_angle_deg' else value})
                changed = True
            elif kind == 'youngs_modulus_pa' and which == str(k):
                matrix, changed = (value, value, value), True
        if changed:
            segments[k] = reinforced(segment, matrix, fibres)
    for name, value in row.items():
        kind, _, which = name.partition('.')
        if not which or kind in FIBRE_NAMES or kind == 'youngs_modulus_pa':
            continue   # done above; inserted_m, backbone_m: the chain's, not the tentacle's
        k = int(which)
        segment = segments[k]
        bend_1, bend_2, twist = segment.modulus_pa
        if kind == 'bend_modulus_pa':
            segment = replace(segment, modulus_pa=(value, value, twist))
        elif kind == 'twist_modulus_pa':
            segment = replace(segment, modulus_pa=(bend_1, bend_2, value))
        elif kind == 'remanence_t':
            m = segment.magnetisation_a_per_m
            segment = replace(segment, magnetisation_a_per_m=value / MU0 * m / np.linalg.norm(m))
        elif kind == 'length_m':
            segment = replace(segment, length_m=value)
        segments[k] = segment
    return replace(spec, segments=tuple(segments))
