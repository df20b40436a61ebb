"""
Many equilibria of one chain in one compiled pass: its magnets' directions and the field vary.

A design study (tentacle_studies) solves the same chain at thousands of points that differ
only in each segment's magnetisation direction and the uniform field. One statics.solve a
point costs 0.15-0.25 ms of Python around a compiled Newton of tens of microseconds; here the
loop over the points is compiled too, and each point starts from the one before (its
neighbour along the grid), so a solve is a few Newton steps. Along a run of points that step
evenly (a grid's last name; 3-DoF joints) the solutions before are extrapolated to the next
point, a parabola through three (a line through two), which saves a Newton step in some:
9.8 us a point on a 24 x 24 grid of 15 deg steps, 102,000 a second (bench/sweep_scale.py).

The same minimisers as statics.solve (spatial_newton.minimise, planar_newton.minimise), the
same tolerance and limits: a point solved here from a state is the point statics.solve finds
from that state (tested). Where several stable equilibria exist, the warm start follows the
branch along the points, as a rig sweeping its field would; a point after one that did not
converge starts straight. Chains with the magnets' interaction are not batched (their loads
are Python callables): solve them one by one.
"""

from dataclasses import dataclass

import numba
import numpy as np
from tentacle_model import (compiled_cache, eigen, planar, planar_newton, spatial,
                            spatial_newton, statics)
from tentacle_model.planar import evaluate as planar_evaluate, smallest_eigenvalue
from tentacle_model.spatial import _evaluate

compiled_cache.fresh(__file__, eigen, planar, planar_newton, spatial, spatial_newton)


@dataclass(frozen=True)
class Batch:
    """Equilibria at P points; world frame, SI units."""

    tips_m: np.ndarray        # (P, 3) the tip
    converged: np.ndarray     # (P,) bool
    stability: np.ndarray     # (P,) smallest Hessian eigenvalue, N m / rad^2 (nan: unknown)
    iterations: np.ndarray    # (P,) Newton steps
    points_m: np.ndarray      # (P, n + 1, 3) joints and tip, base first (if asked; else None)
    twist_stability: np.ndarray = None   # (P,) planar points, if asked: see solve

    @property
    def stable(self):
        """Return (P,) bool: converged with a positive definite Hessian."""
        return self.converged & (self.stability > 0)


def solve(chain, directions, fields_t, gravity_m_s2=(0.0, 0.0, 0.0), dof=3, tol=1e-9,
          max_iterations=200, initial=None, points=False, warm=True, twist=False):
    """
    Return the Batch of a chain's equilibria at P points, each warm-started from the last.

    :param chain: a Chain without interacting magnets (chain.py); its moments' magnitudes
        are kept, their directions come from ``directions``
    :param directions: (P, segments, 3) each segment's magnetisation direction per point,
        link frame (unit vectors; zero rows for passive segments); segments as the chain's
        segment_index numbers them (without one, each link is a segment)
    :param fields_t: (P, 3) the uniform field per point, tesla, world frame
    :param dof: 1 (planar joints) or 3
    :param initial: the first point's start, as statics.solve takes it (default straight)
    :param points: also every point's joints and tip (Batch.points_m)
    :param warm: start each point from the one before (3-DoF: extrapolated along an even run);
        False: every point from ``initial``
        (a tentacle of its own, its field switched on from rest: one equilibrium per point
        where several are stable, whatever order the points come in)
    :param twist: with dof 1, also Batch.twist_stability: the smallest eigenvalue of the 3-DoF
        Hessian at each planar equilibrium, N m / rad^2; below zero the planar shape is
        unstable out of its plane, and twists (thesis chapter 4). nan where the point is not
        converged or not planar (a magnet, the field or gravity out of the plane: the planar
        shape is then no 3-DoF equilibrium)
    :raises ValueError: arrays of the wrong shape or not finite
    """
    directions = np.ascontiguousarray(directions, dtype=float)
    fields = np.ascontiguousarray(fields_t, dtype=float)
    count = len(fields)
    # None: every link a magnet of its own (chain.py)
    index = np.arange(chain.size) if chain.segment_index is None else chain.segment_index
    segments = int(index.max()) + 1 if chain.size else 0
    if fields.shape != (count, 3) or directions.shape != (count, segments, 3):
        raise ValueError(f'directions {directions.shape} and fields {fields.shape}: expected '
                         f'(P, {segments}, 3) and (P, 3)')
    if not (np.all(np.isfinite(directions)) and np.all(np.isfinite(fields))):
        raise ValueError('directions and fields must be finite')
    if dof not in (1, 3):
        raise ValueError(f'dof {dof} is not 1 or 3')
    if twist and dof != 1:
        raise ValueError('twist stability is that of planar equilibria: dof 1')
    gravity = np.asarray(gravity_m_s2, dtype=float)
    statics.check_size(chain.size, dof)
    statics.compile_kernels()
    magnitudes = np.linalg.norm(chain.moments_a_m2, axis=1)
    shape = chain.size * (3 if dof == 3 else 1)
    start = np.zeros(shape) if initial is None else np.asarray(initial, float).reshape(-1)
    if start.shape != (shape,):
        raise ValueError(f'initial angles of {start.size} values for {shape} unknowns')
    newton = np.array([statics.MAX_STEP_RAD, statics.MAX_SADDLE_ESCAPES,
                       statics.ESCAPE_STEP_RAD])
    arguments = (chain.base_rotation, chain.base_position_m, chain.lengths_m, magnitudes,
                 index.astype(np.intp), spatial.gravity_levers(chain),
                 chain.stiffness_n_m, directions, fields, gravity, tol, int(max_iterations),
                 newton, start, points, warm)
    if dof == 3:
        *solved, joints = _spatial_points(*arguments)
        return Batch(*solved, joints if points else None)
    *solved, joints, twisted = _planar_points(*arguments, twist)
    return Batch(*solved, joints if points else None, twisted if twist else None)


@numba.njit(cache=True)
def link_moments(magnitudes, segment_index, directions):
    """Return each link's moment (n, 3), link frame, A m^2: its segment's direction."""
    moments = np.empty((magnitudes.shape[0], 3))
    for link in range(magnitudes.shape[0]):
        moments[link] = magnitudes[link] * directions[segment_index[link]]
    return moments


@numba.njit(cache=True)
def _outputs(count, n, want_points):
    """Return the kernels' (tips, converged, stability, iterations, joints) to fill in."""
    return (np.empty((count, 3)), np.zeros(count, dtype=np.bool_), np.full(count, np.nan),
            np.zeros(count, dtype=np.int64), np.empty((count if want_points else 0, n + 1, 3)))


@numba.njit(cache=True)
def _spatial_points(base_rotation, base_position, lengths, magnitudes, segment_index, levers,
                    stiffness, directions, fields, gravity, tol, max_iterations, newton, start,
                    want_points, warm):
    """Solve every point with the 3-DoF joints: see solve."""
    count, n = fields.shape[0], lengths.shape[0]
    tips, converged, stability, iterations, joints = _outputs(count, n, want_points)
    k_floor = max(1e-9 * np.max(stiffness), 1e-300)
    x = start.copy()
    # the solutions of the points before x's (p - 2, p - 3; nan: none): the predictor's
    history = np.full((2, 3 * n), np.nan)
    for p in range(count):
        moments = link_moments(magnitudes, segment_index, directions[p])
        solved = x   # point p - 1's solution (if it converged)
        if warm:
            x = _predicted(x, history, directions, fields, p)
        x, status, used, _, _, lowest, state = spatial_newton.minimise_state(
            x, base_rotation, base_position, lengths, moments, levers, stiffness, fields[p],
            gravity, tol, k_floor, max_iterations, 0, 0, max_iterations + 1, newton[0],
            int(newton[1]), newton[2], stability[p - 1] if p > 0 else np.nan)
        tips[p] = state[2][n]
        if want_points:
            joints[p] = state[2]
        iterations[p] = used
        if status == spatial_newton.CONVERGED:
            converged[p], stability[p] = True, lowest
        elif status == spatial_newton.AT_ROUND_OFF:
            converged[p], stability[p] = True, eigen.lowest(state[5])
        history[1] = history[0]
        history[0] = solved
        if not (p >= 1 and converged[p - 1]):
            history[0] = np.nan
        if not (converged[p] and np.all(np.isfinite(x))):
            x = np.zeros(3 * n)   # the next point starts straight
            history[:] = np.nan
        if not warm:
            x = start.copy()
    return tips, converged, stability, iterations, joints


@numba.njit(cache=True)
def _predicted(x, history, directions, fields, p):
    """
    Return point p's start: x (point p - 1's solution) extrapolated along the points.

    Where the last points step evenly through the magnets' directions and the field (alike
    in size, turning little: a grid's run), the solutions before x's extend it along the
    curve they trace: a parabola through three, a line through two. Elsewhere (a grid's row
    begins again), x itself.
    """
    out = x.copy()
    if p >= 3 and np.all(np.isfinite(history[1])) and _even(directions, fields, p - 1) \
            and _even(directions, fields, p):
        for i in range(x.shape[0]):
            out[i] = 3.0 * (x[i] - history[0, i]) + history[1, i]
    elif p >= 2 and np.all(np.isfinite(history[0])) and _even(directions, fields, p):
        for i in range(x.shape[0]):
            out[i] = 2.0 * x[i] - history[0, i]
    return out


@numba.njit(cache=True)
def _even(directions, fields, p):
    """Return whether points p - 2, p - 1, p step evenly (sizes alike, turning < 30 deg)."""
    last, step, bend = 0.0, 0.0, 0.0
    for s in range(directions.shape[1]):
        for c in range(3):
            d1 = directions[p - 1, s, c] - directions[p - 2, s, c]
            d2 = directions[p, s, c] - directions[p - 1, s, c]
            last += d1 * d1
            step += d2 * d2
            bend += (d2 - d1) ** 2
    for c in range(3):
        d1 = (fields[p - 1, c] - fields[p - 2, c]) * 100.0   # 10 mT as a unit direction's 1
        d2 = (fields[p, c] - fields[p - 1, c]) * 100.0
        last += d1 * d1
        step += d2 * d2
        bend += (d2 - d1) ** 2
    return last > 0.0 and abs(step - last) <= 1e-6 * last and bend <= 0.25 * last


@numba.njit(cache=True)
def _planar_points(base_rotation, base_position, lengths, magnitudes, segment_index, levers,
                   stiffness, directions, fields, gravity, tol, max_iterations, newton, start,
                   want_points, warm, want_twist):
    """Solve every point with the planar joints (planar.loads per point): see solve."""
    count, n = fields.shape[0], lengths.shape[0]
    tips, converged, stability, iterations, joints = _outputs(count, n, want_points)
    twisted = np.full(count if want_twist else 0, np.nan)
    k = stiffness[:, 0].copy()
    k_floor = max(1e-9 * np.max(k), 1e-300)
    axis_x, axis_y = base_rotation[:, 0].copy(), base_rotation[:, 1].copy()
    gx, gy = axis_x @ gravity, axis_y @ gravity
    x = start.copy()
    a, b = np.empty(n), np.empty(n)
    for p in range(count):
        moments = link_moments(magnitudes, segment_index, directions[p])
        bx, by = axis_x @ fields[p], axis_y @ fields[p]
        load_scale = 0.0
        for i in range(n):   # planar.loads
            a[i] = moments[i, 0] * bx + moments[i, 1] * by + levers[i] * gx
            b[i] = moments[i, 0] * by - moments[i, 1] * bx + levers[i] * gy
            load_scale = max(load_scale, abs(a[i]) + abs(b[i]))
        x, status, used, _, _, lowest = planar_newton.minimise(
            x, k, a, b, load_scale, tol, k_floor, max_iterations, 0, 0, max_iterations + 1,
            newton[0], int(newton[1]), newton[2])
        tip = base_position.copy()
        if want_points:
            joints[p, 0] = tip
        for i in range(n):
            c, s = np.cos(x[i]), np.sin(x[i])
            tip += lengths[i] * (c * axis_x + s * axis_y)
            if want_points:
                joints[p, i + 1] = tip
        tips[p] = tip
        iterations[p] = used
        if status == spatial_newton.CONVERGED:
            converged[p], stability[p] = True, lowest
        elif status == spatial_newton.AT_ROUND_OFF:
            banded = planar_evaluate(x, k, a, b, False, True)[2]
            converged[p] = True
            stability[p] = smallest_eigenvalue(banded[1], banded[0, 1:])
        if want_twist and converged[p]:
            twisted[p] = _out_of_plane_stability(x, base_rotation, base_position, lengths,
                                                 moments, levers, stiffness, fields[p],
                                                 gravity, tol, k_floor)
        if not (converged[p] and np.all(np.isfinite(x))):
            x = np.zeros(n)
        if not warm:
            x = start.copy()
    return tips, converged, stability, iterations, joints, twisted


@numba.njit(cache=True)
def _out_of_plane_stability(headings, base_rotation, base_position, lengths, moments, levers,
                            stiffness, field, gravity, tol, k_floor):
    """Return the 3-DoF Hessian's smallest eigenvalue at a planar state (nan: not planar)."""
    n = headings.shape[0]
    q = np.zeros((n, 3))
    q[0, 0] = headings[0]
    for i in range(1, n):   # the planar joints' headings, as the 3-DoF joints' first angles
        q[i, 0] = headings[i] - headings[i - 1]
    state = _evaluate(q, base_rotation, base_position, lengths, moments, levers, stiffness,
                      field, gravity, True)
    # out of the plane, its gradient is zero only where every load lies in the plane
    if np.max(np.abs(state[4])) > 1e3 * tol * max(state[8], k_floor):
        return np.nan
    return eigen.lowest(state[5])
