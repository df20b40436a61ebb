"""
The planar (1-DoF) equilibrium compiled end to end: statics' damped Newton on a tridiagonal.

For a planar chain in a uniform field and gravity alone (no link loads), statics.solve runs
its minimiser here: the steps of statics._minimise with _Planar's Newton step (a positive
definite tridiagonal solve, LAPACK dpttrf's recurrence; shifted just past the smallest
eigenvalue where it is not positive definite), its torque scale and its saddle escapes, in
one compiled call of up to ``steps`` Newton steps. The caller checks its deadline between
calls and resumes from the state returned; the status codes are spatial_newton's.
"""

import numba
import numpy as np
from tentacle_model import compiled_cache, eigen, planar, spatial_newton
from tentacle_model.planar import evaluate, smallest_eigenvalue
from tentacle_model.spatial_newton import (AT_ROUND_OFF, CONVERGED, LINE_SEARCH_FAILED,
                                           NON_FINITE, OUT_OF_ITERATIONS, RUNNING)

compiled_cache.fresh(__file__, eigen, planar, spatial_newton)


@numba.njit(cache=True)
def _tridiagonal_solve(diagonal, off, rhs):
    """Return (x, factorised): T x = rhs by T = L D L^T; False where T is not positive definite."""
    n = diagonal.shape[0]
    d = np.empty(n)
    ratio = np.empty(max(n - 1, 0))
    d[0] = diagonal[0]
    if not d[0] > 0.0:
        return rhs, False
    for i in range(n - 1):
        ratio[i] = off[i] / d[i]
        d[i + 1] = diagonal[i + 1] - ratio[i] * off[i]
        if not d[i + 1] > 0.0:
            return rhs, False
    x = rhs.copy()
    for i in range(1, n):
        x[i] -= ratio[i - 1] * x[i - 1]
    x[n - 1] /= d[n - 1]
    for i in range(n - 2, -1, -1):
        x[i] = x[i] / d[i] - ratio[i] * x[i + 1]
    return x, True


@numba.njit(cache=True)
def _newton_step(diagonal, off, g):
    """Return -H^-1 g for a tridiagonal H, shifted just past positive where it is not (_Planar)."""
    n = diagonal.shape[0]
    scale = max(np.max(np.abs(diagonal)), 1e-300)
    if n == 1:
        return -g / (diagonal[0] if diagonal[0] > 0 else abs(diagonal[0]) + 1e-8 * scale)
    step, ok = _tridiagonal_solve(diagonal, off, -g)
    if ok:
        return step
    shift = -smallest_eigenvalue(diagonal, off) + 1e-6 * scale
    step, ok = _tridiagonal_solve(diagonal + shift, off, -g)
    if ok:
        return step
    shift = 0.0
    for _ in range(40):   # statics._shifted_solve: a growing shift until it factorises
        step, ok = _tridiagonal_solve(diagonal + shift, off, g)
        if ok:
            return -step
        shift = max(shift * 10.0, 1e-8 * scale)
    return -g / scale


@numba.njit(cache=True)
def _torque_scale(theta, k, load_scale, k_floor):
    largest = load_scale
    previous = 0.0
    for i in range(theta.shape[0]):
        largest = max(largest, abs(k[i] * (theta[i] - previous)))
        previous = theta[i]
    return max(largest, k_floor)


@numba.njit(cache=True)
def minimise(x, k, a, b, load_scale, tol, k_floor, max_iterations, iterations, escapes, steps,
             max_step_rad, max_escapes, escape_step_rad):
    """
    Return (x, status, iterations, escapes, residual, stability) after up to steps Newton steps.

    x: the absolute link angles (n,); a, b: planar.loads' coefficients; load_scale their
    largest |a| + |b|. As spatial_newton.minimise otherwise; stability is the smallest
    eigenvalue of the planar Hessian where status is CONVERGED, else nan.
    """
    done = 0
    n = x.shape[0]
    while True:
        energy, g, banded = evaluate(x, k, a, b, False, True)
        diagonal, off = banded[1], banded[0, 1:]
        residual = np.max(np.abs(g)) / _torque_scale(x, k, load_scale, k_floor)
        if not np.isfinite(residual):
            return x, NON_FINITE, iterations, escapes, residual, np.nan
        if residual <= tol:
            lowest = smallest_eigenvalue(diagonal, off)
            if lowest < -1e-9 * np.max(np.abs(diagonal)) and escapes < max_escapes:
                escapes += 1
                mode = np.ones(1)
                if n > 1:
                    dense = np.diag(diagonal) + np.diag(off, 1) + np.diag(off, -1)
                    mode = np.linalg.eigh(dense)[1][:, 0]
                total = mode.sum()
                sign = 1.0 if total == 0.0 else np.sign(total)
                x = x + escape_step_rad * sign * mode / np.max(np.abs(mode))
                continue
            return x, CONVERGED, iterations, escapes, residual, lowest
        if iterations >= max_iterations:
            return x, OUT_OF_ITERATIONS, iterations, escapes, residual, np.nan
        if done >= steps:
            return x, RUNNING, iterations, escapes, residual, np.nan
        iterations += 1
        done += 1
        step = _newton_step(diagonal, off, g)
        biggest = np.max(np.abs(step))
        if biggest > max_step_rad:
            step = step * (max_step_rad / biggest)
        slope = g @ step
        largest_g = np.max(np.abs(g))
        alpha = 1.0
        accepted = False
        while alpha > 1e-12:
            trial = x + alpha * step
            u = evaluate(trial, k, a, b, False, False)[0]
            if u <= energy + 1e-4 * alpha * slope:
                accepted = True
                break
            if abs(u - energy) <= 1e-13 * abs(energy) and np.max(np.abs(
                    evaluate(trial, k, a, b, False, True)[1])) < largest_g:
                accepted = True
                break   # energy changes are round-off here: let the gradient decide
            alpha *= 0.5
        if not accepted:
            status = AT_ROUND_OFF if residual <= 1e3 * tol else LINE_SEARCH_FAILED
            return x, status, iterations, escapes, residual, np.nan
        x = trial
