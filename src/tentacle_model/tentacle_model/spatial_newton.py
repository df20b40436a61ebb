"""
The 3-DoF equilibrium compiled end to end: statics' damped Newton, and its sensitivities.

For a chain in a uniform field and gravity alone (no link loads), statics.solve runs its
minimiser here: the steps of statics._minimise (Newton, shifted just past positive where
the Hessian is indefinite, a step cap, an Armijo line search on the energy, saddle escapes)
in one compiled call of up to ``steps`` Newton steps. A 5-link solve then costs tens of
microseconds rather than 0.3 ms of Python calls; the caller checks its deadline between
calls and resumes from the state returned.

``sensitivities`` differentiates an equilibrium implicitly (model.py's docstring), for the
field and every link's moment at once: one factorisation of the Hessian, one pass.
"""

import numba
import numpy as np
from tentacle_model import compiled_cache, eigen, spatial
from tentacle_model.spatial import _evaluate

compiled_cache.fresh(__file__, eigen, spatial)

RUNNING, CONVERGED, NON_FINITE, OUT_OF_ITERATIONS, LINE_SEARCH_FAILED, AT_ROUND_OFF = range(6)
# Unknowns up to which eigen.cholesky beats numba's LAPACK call (its copy and checks): 0.37
# against 0.56 us at 15, 2.0 against 1.8 at 30, 3x slower at 150 (blocked LAPACK wins).
WRITTEN_OUT_CHOLESKY = 24


@numba.njit(cache=True)
def _max_abs(v):
    """Return max |v_i| of a 1-D v, in one pass (no temporary); nan if any is, as np.max."""
    largest = 0.0
    for i in range(v.shape[0]):
        size = abs(v[i])
        if size != size:
            return np.nan
        largest = max(largest, size)
    return largest


@numba.njit(cache=True)
def _newton_step(h, g):
    """Return -H^-1 g, shifting an indefinite H just past positive (statics' rule)."""
    if g.shape[0] <= WRITTEN_OUT_CHOLESKY:
        factor, positive = eigen.cholesky(h)
        if positive:
            return -eigen.cholesky_solve(factor, g)
    else:
        try:
            return -eigen.cholesky_solve(np.linalg.cholesky(h), g)
        except Exception:  # not positive definite
            pass
    lowest = np.linalg.eigvalsh(h)[0]
    shift = -lowest + 1e-6 * max(np.max(np.abs(np.diag(h))), 1e-300)
    return -np.linalg.solve(h + shift * np.eye(g.shape[0]), g)


@numba.njit(cache=True)
def minimise(x, base_rotation, base_position, lengths, moments, levers, stiffness, field,
             gravity, tol, k_floor, max_iterations, iterations, escapes, steps, max_step_rad,
             max_escapes, escape_step_rad):
    """
    Return (x, status, iterations, escapes, residual, stability) after up to steps Newton steps.

    x: the flattened (3n,) joint angles; status one of this module's codes (RUNNING: the
    steps are spent, call again from x with the iterations and escapes returned); stability
    the smallest Hessian eigenvalue where status is CONVERGED, else nan.
    """
    return minimise_state(x, base_rotation, base_position, lengths, moments, levers,
                          stiffness, field, gravity, tol, k_floor, max_iterations, iterations,
                          escapes, steps, max_step_rad, max_escapes, escape_step_rad,
                          np.nan)[:6]


@numba.njit(cache=True)
def minimise_state(x, base_rotation, base_position, lengths, moments, levers, stiffness,
                   field, gravity, tol, k_floor, max_iterations, iterations, escapes, steps,
                   max_step_rad, max_escapes, escape_step_rad, stability_near):
    """
    Return minimise's values, then spatial._evaluate's tuple at the x returned (its Hessian in).

    A batch takes the tip (and, where round-off ended the search, the stability) from it
    rather than evaluating the chain once more; stability_near (a neighbouring point's, or
    nan) starts the search for this one's.
    """
    done = 0
    n = x.shape[0] // 3
    state = _evaluate(x.reshape(n, 3), base_rotation, base_position, lengths, moments,
                      levers, stiffness, field, gravity, True)
    while True:
        energy, g, h, largest = state[3], state[4].reshape(-1), state[5], state[8]
        largest_g = _max_abs(g)
        residual = largest_g / max(largest, k_floor)
        if not np.isfinite(residual):
            return x, NON_FINITE, iterations, escapes, residual, np.nan, state
        if residual <= tol:
            # 2-3 us (LAPACK's whole spectrum: 8); its search starts 10% below a neighbour's
            # value where a Sturm count says no eigenvalue lies lower
            lowest = eigen.lowest(h, stability_near - 0.1 * abs(stability_near))
            diag_scale = np.max(np.abs(np.diag(h)))
            if lowest < -1e-9 * diag_scale and escapes < max_escapes:
                escapes += 1
                mode = np.linalg.eigh(h)[1][:, 0]
                total = mode.sum()
                sign = 1.0 if total == 0.0 else np.sign(total)
                x = x + escape_step_rad * sign * mode / np.max(np.abs(mode))
                state = _evaluate(x.reshape(n, 3), base_rotation, base_position, lengths,
                                  moments, levers, stiffness, field, gravity, True)
                continue
            return x, CONVERGED, iterations, escapes, residual, lowest, state
        if iterations >= max_iterations:
            return x, OUT_OF_ITERATIONS, iterations, escapes, residual, np.nan, state
        if done >= steps:
            return x, RUNNING, iterations, escapes, residual, np.nan, state
        iterations += 1
        done += 1
        step = _newton_step(h, g)
        biggest = _max_abs(step)
        if biggest > max_step_rad:
            step = step * (max_step_rad / biggest)
        slope = 0.0
        for i in range(step.shape[0]):   # not g @ step: BLAS' call costs more than 15 terms
            slope += g[i] * step[i]
        alpha = 1.0
        accepted = False
        while alpha > 1e-12:
            trial = np.empty_like(x)
            for i in range(x.shape[0]):
                trial[i] = x[i] + alpha * step[i]
            # the full step is nearly always taken: its Hessian is the next iteration's
            trial_state = _evaluate(trial.reshape(n, 3), base_rotation, base_position,
                                    lengths, moments, levers, stiffness, field, gravity,
                                    alpha == 1.0)
            u = trial_state[3]
            if u <= energy + 1e-4 * alpha * slope:
                accepted = True
                break
            if abs(u - energy) <= 1e-13 * abs(energy) and np.max(np.abs(
                    trial_state[4])) < largest_g:
                accepted = True
                break   # energy changes are round-off here: let the gradient decide
            alpha *= 0.5
        if not accepted:
            status = AT_ROUND_OFF if residual <= 1e3 * tol else LINE_SEARCH_FAILED
            return x, status, iterations, escapes, residual, np.nan, state
        x = trial
        state = trial_state if alpha == 1.0 else _evaluate(
            x.reshape(n, 3), base_rotation, base_position, lengths, moments, levers,
            stiffness, field, gravity, True)


@numba.njit(cache=True)
def sensitivities(rotations, axes, points, distal_moments, hessian, field, free):
    """
    Return an equilibrium's derivatives by the field and by each link's moment.

    From spatial._evaluate's pass at the equilibrium, in the free angles (indices into the
    flattened (3n,) joint angles: all of them for 3-DoF joints, every third, bend_1, for
    planar ones): (dq/dB (N, 3) rad/T, dq/dm (N, 3n) rad per A m^2, dp/dB (n + 1, 3, 3)
    m/T, dp/dm (n + 1, 3, 3n)); m is each link's moment in its own frame, columns (link,
    component). H dq = -(dg/dp) dp at the equilibrium, with dg/dB = -(a_e x V_J(e)) and
    dg/dm_i = -R_i^T (B x a_e) for links i >= J(e).
    """
    n = rotations.shape[0]
    size, count = 3 * n, free.shape[0]
    rhs = np.zeros((count, 3 + size))   # -dg/dp: [field | moments]
    reduced = np.empty((count, count))
    for row in range(count):
        e = free[row]
        for column in range(count):
            reduced[row, column] = hessian[e, free[column]]
        j, a = e // 3, axes[e // 3, e % 3]
        v = distal_moments[j]
        rhs[row, 0] = a[1] * v[2] - a[2] * v[1]
        rhs[row, 1] = a[2] * v[0] - a[0] * v[2]
        rhs[row, 2] = a[0] * v[1] - a[1] * v[0]
        bxa0 = field[1] * a[2] - field[2] * a[1]
        bxa1 = field[2] * a[0] - field[0] * a[2]
        bxa2 = field[0] * a[1] - field[1] * a[0]
        for i in range(j, n):
            for c in range(3):
                rhs[row, 3 + 3 * i + c] = (rotations[i, 0, c] * bxa0
                                           + rotations[i, 1, c] * bxa1
                                           + rotations[i, 2, c] * bxa2)
    dq = np.linalg.solve(reduced, rhs)
    # d p_k / d q_e = a_e x (p_k - p_J(e)) for points k past joint J(e)
    dp = np.zeros((n + 1, 3, 3 + size))
    for row in range(count):
        e = free[row]
        j, a = e // 3, axes[e // 3, e % 3]
        for k in range(j + 1, n + 1):
            lever0 = points[k, 0] - points[j, 0]
            lever1 = points[k, 1] - points[j, 1]
            lever2 = points[k, 2] - points[j, 2]
            c0 = a[1] * lever2 - a[2] * lever1
            c1 = a[2] * lever0 - a[0] * lever2
            c2 = a[0] * lever1 - a[1] * lever0
            for p in range(3 + size):
                dp[k, 0, p] += c0 * dq[row, p]
                dp[k, 1, p] += c1 * dq[row, p]
                dp[k, 2, p] += c2 * dq[row, p]
    return (np.ascontiguousarray(dq[:, :3]), np.ascontiguousarray(dq[:, 3:]),
            np.ascontiguousarray(dp[:, :, :3]), np.ascontiguousarray(dp[:, :, 3:]))
