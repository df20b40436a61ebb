"""
One key step of the planner's objective, compiled: its equilibrium, residuals and Jacobian.

optimise.Problem.residuals for a model without magnet-to-magnet interaction: the step's
equilibrium from the state carried from the step before (spatial_newton.minimise for 3-DoF
joints, planar_newton.minimise for planar ones: the steps statics.solve takes), its
stability (the smallest 3-DoF Hessian eigenvalue), the shape residuals against its target,
the keep-off residuals of every link against every obstacle and wall
(clearance.link_gap_gradients), and their derivatives by the magnetisation angles and the
step's field unknowns through the equilibrium's sensitivities, in one call. Python's part
of a 5-step evaluation was three quarters of its 1.2 ms: numpy calls on arrays of a few
dozen numbers.

Rows: the shape's (n + 1) 3, one left zero for the caller's stability penalty, then one per
link and obstacle or wall. Columns: the direction angles (n_dir), then the step's field
unknowns. The kernels' arguments:

- start: (n, 3) joint angles to solve from, rad
- magnitudes: (n,) each link's moment magnitude, A m^2; segment_index (n,) its
    segment; directions (segments, 3) each segment's unit magnetisation, link frame
- newton: (max step rad, saddle escapes, escape step rad): statics' constants
- free: the model's angles in the flattened (3n,) joint angles
- target: (n + 1, 3) m; weight: the shape rows' scale, 1/m
- centres, radii, wall_points, wall_ends: the obstacles and walls (gap_arrays)
- margin: m; keep_scale: the keep-off rows' scale, 1/m
- direction_derivatives: (segments, angles, 3) d direction / d angle; first_column
    (segments,) the column of a segment's first angle (-1: held); n_dir: angle columns
- field_map: (3, field unknowns): d field (T) / d field unknown, in the columns
    from field_column
- r: (rows,) zeros, and jac: (rows, unknowns) zeros (unused without jacobian): the
    step's rows, written here
"""

import numba
import numpy as np
from tentacle_model import (batch, compiled_cache, eigen, planar, planar_newton, spatial,
                            spatial_newton)
from tentacle_model.batch import link_moments
from tentacle_model.spatial import _evaluate
from tentacle_model.spatial_newton import AT_ROUND_OFF, CONVERGED, sensitivities
from tentacle_planner import clearance
from tentacle_planner.clearance import gap_gradients

compiled_cache.fresh(__file__, batch, eigen, planar, planar_newton, spatial, spatial_newton,
                     clearance)

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
                   newton, free, target, weight, link_radii, centres, radii, wall_points,
                   wall_ends, margin, keep_scale, direction_derivatives, first_column, n_dir,
                   field_map, field_column, r, jac, jacobian):
    """Return (state (n, 3), usable, stability) of a 3-DoF key step; write its rows (_rows)."""
    n = lengths.shape[0]
    moments = link_moments(magnitudes, segment_index, directions)
    x, status, _, _, _, stability = spatial_newton.minimise(
        start.reshape(-1).copy(), base_rotation, base_position, lengths, moments, levers,
        stiffness, field, gravity, tol, k_floor, max_iterations, 0, 0, max_iterations + 1,
        newton[0], int(newton[1]), newton[2])
    state = x.reshape(n, 3)
    if status != CONVERGED:
        stability = np.nan   # _rows finds it
    usable, stability = _rows(
        state, np.zeros((0, 3)), status, stability, moments, base_rotation, base_position,
        lengths, magnitudes, segment_index, levers, stiffness, field, gravity, free, target,
        weight, link_radii, centres, radii, wall_points, wall_ends, margin, keep_scale,
        direction_derivatives, first_column, n_dir, field_map, field_column, r, jac, jacobian)
    return state, usable, stability


@numba.njit(cache=True)
def planar_step_residuals(start, base_rotation, base_position, lengths, magnitudes,
                          segment_index, directions, levers, stiffness, field, gravity, tol,
                          k_floor, max_iterations, newton, free, target, weight, link_radii,
                          centres, radii, wall_points, wall_ends, margin, keep_scale,
                          direction_derivatives, first_column, n_dir, field_map, field_column,
                          r, jac, jacobian):
    """Return (state (n, 3), usable, stability) of a planar key step; write its rows (_rows)."""
    n = lengths.shape[0]
    moments = link_moments(magnitudes, segment_index, directions)
    # planar.loads: each link's torque coefficients in the base plane
    bx = base_rotation[0, 0] * field[0] + base_rotation[1, 0] * field[1] \
        + base_rotation[2, 0] * field[2]
    by = base_rotation[0, 1] * field[0] + base_rotation[1, 1] * field[1] \
        + base_rotation[2, 1] * field[2]
    gx = base_rotation[0, 0] * gravity[0] + base_rotation[1, 0] * gravity[1] \
        + base_rotation[2, 0] * gravity[2]
    gy = base_rotation[0, 1] * gravity[0] + base_rotation[1, 1] * gravity[1] \
        + base_rotation[2, 1] * gravity[2]
    a = moments[:, 0] * bx + moments[:, 1] * by + levers * gx
    b = moments[:, 0] * by - moments[:, 1] * bx + levers * gy
    theta, status, _, _, _, _ = planar_newton.minimise(
        np.cumsum(start[:, 0]), stiffness[:, 0].copy(), a, b, np.max(np.abs(a) + np.abs(b)),
        tol, k_floor, max_iterations, 0, 0, max_iterations + 1, newton[0], int(newton[1]),
        newton[2])
    state = np.zeros((n, 3))
    state[0, 0] = theta[0]
    state[1:, 0] = theta[1:] - theta[:-1]
    points = np.empty((n + 1, 3))   # planar.points
    u = v = 0.0
    points[0] = base_position
    for i in range(n):
        u += lengths[i] * np.cos(theta[i])
        v += lengths[i] * np.sin(theta[i])
        for c in range(3):
            points[i + 1, c] = base_position[c] + u * base_rotation[c, 0] \
                + v * base_rotation[c, 1]
    usable, stability = _rows(
        state, points, status, np.nan, moments, base_rotation, base_position, lengths,
        magnitudes, segment_index, levers, stiffness, field, gravity, free, target, weight,
        link_radii, centres, radii, wall_points, wall_ends, margin, keep_scale,
        direction_derivatives, first_column, n_dir, field_map, field_column, r, jac, jacobian)
    return state, usable, stability


@numba.njit(cache=True)
def _rows(state, points, status, stability, moments, base_rotation, base_position, lengths,
          magnitudes, segment_index, levers, stiffness, field, gravity, free, target, weight,
          link_radii, centres, radii, wall_points, wall_ends, margin, keep_scale,
          direction_derivatives, first_column, n_dir, field_map, field_column, r, jac,
          jacobian):
    """
    Return (usable, stability) of a solved key step, and write its rows of r and J.

    Usable: converged, its points finite (else its shape rows are FAILED_RESIDUAL, J zero).
    points: the model's own ((0, 3): the 3-DoF pass's); stability: nan for the smallest
    eigenvalue of the 3-DoF Hessian at the state.
    """
    n = lengths.shape[0]
    rotations, axes, chain_points, _, _, hessian, distal, _, _ = _evaluate(
        state, base_rotation, base_position, lengths, moments, levers, stiffness, field,
        gravity, True)
    if points.shape[0] == 0:
        points = chain_points
    if np.isnan(stability):
        stability = np.linalg.eigvalsh(hessian)[0]
    shape_rows = 3 * (n + 1)
    columns = radii.shape[0] + wall_ends.shape[0]
    if not (status == CONVERGED or status == AT_ROUND_OFF) or not np.all(np.isfinite(points)):
        r[:shape_rows + 1] = FAILED_RESIDUAL   # outside what the rig can rely on
        return False, stability
    for k in range(n + 1):
        for c in range(3):
            r[3 * k + c] = weight * (points[k, c] - target[k, c])
    gaps, gradients = gap_gradients(points, link_radii, centres, radii, wall_points, wall_ends)
    for link in range(n):
        for j in range(columns):
            if gaps[link, j] < margin:
                r[shape_rows + 1 + link * columns + j] = keep_scale * (margin - gaps[link, j])
    if not jacobian:
        return True, stability
    _, _, dp_field, dp_moment = sensitivities(rotations, axes, chain_points, distal, hessian,
                                              field, free)
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
    return True, stability
