"""
One key step of the planner's objective, compiled: its equilibrium, residuals and Jacobian.

optimise.Problem.residuals for a 3-DoF model without magnet-to-magnet interaction: the
step's state carried from the step before, its equilibrium (spatial_newton.minimise, the
steps statics.solve takes), the shape residuals against its target, the keep-off residuals
of every link against every obstacle and wall (clearance.link_gap_gradients), and their
derivatives by the magnetisation angles and the step's field unknowns through the
equilibrium's sensitivities, in one call. Python's part of a 5-step evaluation was three
quarters of its 1.2 ms: numpy calls on arrays of a few dozen numbers.

Rows: the shape's (n + 1) 3, one left zero for the caller's stability penalty, then one per
link and obstacle or wall. Columns: the direction angles (n_dir), then the step's field
unknowns.
"""

import numba
import numpy as np
from tentacle_model import compiled_cache, spatial, spatial_newton
from tentacle_model.spatial import _evaluate
from tentacle_model.spatial_newton import AT_ROUND_OFF, CONVERGED, minimise, sensitivities
from tentacle_planner import clearance
from tentacle_planner.clearance import gap_gradients

compiled_cache.fresh(__file__, spatial, spatial_newton, clearance)

FAILED_RESIDUAL = 10.0   # each shape row of a step that did not converge (or is not finite)


@numba.njit(cache=True)
def carried(previous, index):
    """Return the start state (n, 3): previous[index[i]] where index[i] >= 0, else straight."""
    out = np.zeros((index.shape[0], 3))
    for i in range(index.shape[0]):
        if index[i] >= 0:
            out[i] = previous[index[i]]
    return out


@numba.njit(cache=True)
def step_residuals(start, base_rotation, base_position, lengths, magnitudes, segment_index,
                   directions, levers, stiffness, field, gravity, tol, k_floor, max_iterations,
                   newton, target, weight, link_radii, centres, radii, wall_points, wall_ends,
                   margin, keep_scale, direction_derivatives, first_column, n_dir, field_map,
                   field_column, r, jac, jacobian):
    """
    Return (state (n, 3), usable, stability) of one key step; write its rows of r and J.

    Usable: converged, its points finite (else its shape rows are FAILED_RESIDUAL, J zero).

    :param start: (n, 3) joint angles to solve from, rad
    :param magnitudes: (n,) each link's moment magnitude, A m^2; segment_index (n,) its
        segment; directions (segments, 3) each segment's unit magnetisation, link frame
    :param newton: (max step rad, saddle escapes, escape step rad): statics' constants
    :param target: (n + 1, 3) m; weight: the shape rows' scale, 1/m
    :param centres, radii, wall_points, wall_ends: the obstacles and walls (gap_arrays)
    :param margin: m; keep_scale: the keep-off rows' scale, 1/m
    :param direction_derivatives: (segments, angles, 3) d direction / d angle; first_column
        (segments,) the column of a segment's first angle (-1: held); n_dir: angle columns
    :param field_map: (3, field unknowns): d field (T) / d field unknown, in the columns
        from field_column
    :param r: (rows,) zeros, and jac: (rows, unknowns) zeros (unused without jacobian): the
        step's rows, written here
    """
    n = lengths.shape[0]
    moments = np.empty((n, 3))
    for link in range(n):
        moments[link] = magnitudes[link] * directions[segment_index[link]]
    x, status, _, _, _, stability = minimise(
        start.reshape(-1).copy(), base_rotation, base_position, lengths, moments, levers,
        stiffness, field, gravity, tol, k_floor, max_iterations, 0, 0, max_iterations + 1,
        newton[0], int(newton[1]), newton[2])
    state = x.reshape(n, 3)
    rotations, axes, points, _, _, hessian, distal, _, _ = _evaluate(
        state, base_rotation, base_position, lengths, moments, levers, stiffness, field,
        gravity, True)
    if status == AT_ROUND_OFF:
        stability = np.linalg.eigvalsh(hessian)[0]
    shape_rows = 3 * (n + 1)
    columns = radii.shape[0] + wall_ends.shape[0]
    if not (status == CONVERGED or status == AT_ROUND_OFF) or not np.all(np.isfinite(points)):
        r[:shape_rows + 1] = FAILED_RESIDUAL   # outside what the rig can rely on
        return state, False, stability
    for k in range(n + 1):
        for c in range(3):
            r[3 * k + c] = weight * (points[k, c] - target[k, c])
    gaps, gradients = gap_gradients(points, link_radii, centres, radii, wall_points, wall_ends)
    for link in range(n):
        for j in range(columns):
            if gaps[link, j] < margin:
                r[shape_rows + 1 + link * columns + j] = keep_scale * (margin - gaps[link, j])
    if not jacobian:
        return state, True, stability
    _, _, dp_field, dp_moment = sensitivities(rotations, axes, points, distal, hessian, field)
    # d points / d unknowns: the direction angles, then the field unknowns
    angles, field_size = direction_derivatives.shape[1], field_map.shape[1]
    by = np.zeros((n + 1, 3, n_dir + field_size))
    for k in range(n + 1):
        for c in range(3):
            for f in range(field_size):
                by[k, c, n_dir + f] = (dp_field[k, c, 0] * field_map[0, f]
                                       + dp_field[k, c, 1] * field_map[1, f]
                                       + dp_field[k, c, 2] * field_map[2, f])
            for link in range(n):
                s = segment_index[link]
                if first_column[s] < 0:
                    continue
                for a in range(angles):
                    d = direction_derivatives[s, a]
                    by[k, c, first_column[s] + a] += magnitudes[link] * (
                        dp_moment[k, c, 3 * link] * d[0] + dp_moment[k, c, 3 * link + 1] * d[1]
                        + dp_moment[k, c, 3 * link + 2] * d[2])
    rows = np.zeros((r.shape[0], n_dir + field_size))
    for k in range(n + 1):
        for c in range(3):
            rows[3 * k + c] = weight * by[k, c]
    for link in range(n):
        for j in range(columns):
            if gaps[link, j] < margin:
                row = shape_rows + 1 + link * columns + j
                for c in range(3):
                    rows[row] -= keep_scale * (gradients[link, j, 0, c] * by[link, c]
                                               + gradients[link, j, 1, c] * by[link + 1, c])
    jac[:, :n_dir] = rows[:, :n_dir]
    jac[:, field_column:field_column + field_size] = rows[:, n_dir:]
    return state, True, stability
