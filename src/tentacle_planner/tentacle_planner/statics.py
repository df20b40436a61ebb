"""
Forward statics: the equilibrium of a chain in a uniform field, by minimising its energy.

Newton's method on the analytic gradient and Hessian, with a Levenberg shift where the
Hessian is not positive definite, a step cap and an Armijo line search on the energy. The
start is the caller's previous state (warm start): quasi-static history decides which branch
the rod is on. A converged point whose Hessian has a negative eigenvalue is a saddle, not a
minimum: the solver pushes off along that eigenvector and minimises again (a bounded number
of times). Every result says whether it converged and why, with the iteration count, the
residual and the stability (the smallest Hessian eigenvalue: negative or near zero means
unstable or at a bifurcation). It never returns NaN silently.

Only planar (1-DoF joint) chains are solved so far; 3-DoF joints are the next step.
"""

from dataclasses import dataclass
import time

import numpy as np
from scipy.linalg import eigh_tridiagonal, LinAlgError, solveh_banded

from tentacle_planner import planar

MAX_STEP_RAD = 0.5       # largest change of any link angle in one Newton step
MAX_SADDLE_ESCAPES = 5
ESCAPE_STEP_RAD = 0.05


@dataclass(frozen=True)
class Equilibrium:
    """A solve's result; arrays over links base first, SI units."""

    angles_rad: np.ndarray    # (n,) absolute link angles in the base plane
    points_m: np.ndarray      # (n + 1, 3) joints and tip, world frame
    converged: bool
    reason: str
    iterations: int
    residual: float           # max |dU/dtheta| over the torque scale of the loads
    stability: float          # smallest Hessian eigenvalue, N m / rad^2 (nan if unknown)
    energy_j: float

    @property
    def tip_m(self):
        """Return the tip position (3,), m."""
        return self.points_m[-1]

    @property
    def heading(self):
        """Return the tip's unit direction (3,) in the world frame."""
        step = self.points_m[-1] - self.points_m[-2] if len(self.points_m) > 1 else None
        if step is None:
            return np.array([1.0, 0.0, 0.0])
        return step / np.linalg.norm(step)


def _smallest_eigen(banded):
    """Return (smallest eigenvalue, its eigenvector) of a banded symmetric tridiagonal."""
    if banded.shape[1] == 1:
        return float(banded[1, 0]), np.ones(1)
    values, vectors = eigh_tridiagonal(banded[1], banded[0, 1:], select='i',
                                       select_range=(0, 0))
    return float(values[0]), vectors[:, 0]


def _newton_direction(banded, g):
    """Return a descent direction: a (shifted where needed) Newton step."""
    shift = 0.0
    scale = max(np.max(np.abs(banded[1])), 1e-300)
    if banded.shape[1] == 1:  # one link: LAPACK's banded solver needs two
        curvature = banded[1, 0]
        return -g / (curvature if curvature > 0 else abs(curvature) + 1e-8 * scale)
    for _ in range(40):
        shifted = banded.copy()
        shifted[1] += shift
        try:
            return -solveh_banded(shifted, g, check_finite=False)
        except LinAlgError:
            shift = max(shift * 10.0, 1e-8 * scale)
    return -g / scale


def solve_planar(chain, field_t, gravity_m_s2=(0.0, 0.0, 0.0), initial=None, tol=1e-9,
                 max_iterations=500, time_limit_s=10.0):
    """
    Return the Equilibrium of a planar chain.

    :param chain: a Chain (chain.py)
    :param field_t: (3,) uniform field, tesla, world frame
    :param gravity_m_s2: (3,) gravity, world frame (zero: no gravity)
    :param initial: (n,) link angles to start from (the previous state), rad
    :param tol: converged when max |dU/dtheta| <= tol * torque scale
    """
    n = chain.size
    if n == 0:
        return Equilibrium(np.zeros(0), chain.base_position_m[None, :].copy(), True,
                           'nothing inserted', 0, 0.0, np.nan, 0.0)
    field_t = np.asarray(field_t, dtype=float)
    gravity_m_s2 = np.asarray(gravity_m_s2, dtype=float)
    if not (np.all(np.isfinite(field_t)) and np.all(np.isfinite(gravity_m_s2))):
        raise ValueError(f'field {field_t} T and gravity {gravity_m_s2} m/s^2 must be finite')
    k = chain.stiffness_n_m[:, 0]
    a, b = planar.loads(chain, field_t, gravity_m_s2)
    theta = np.zeros(n) if initial is None else np.array(initial, dtype=float)
    if theta.shape != (n,) or not np.all(np.isfinite(theta)):
        raise ValueError(f'initial angles must be {n} finite numbers')
    load_scale = max(np.max(np.abs(a) + np.abs(b)), 1e-9 * np.max(k), 1e-300)
    deadline = time.monotonic() + time_limit_s
    iterations = escapes = 0
    reason = ''
    while True:
        g = planar.gradient(theta, k, a, b)
        # Relative to the largest torque in the balance, so round-off sets the same floor
        # whether the loads or the springs dominate.
        scale = max(load_scale, np.max(np.abs(k * np.diff(theta, prepend=0.0))))
        residual = float(np.max(np.abs(g)) / scale)
        if not np.isfinite(residual):
            reason = 'non-finite gradient'
            break
        if residual <= tol:
            banded = planar.hessian_banded(theta, k, a, b)
            stability, mode = _smallest_eigen(banded)
            if stability < -1e-9 * np.max(banded[1]) and escapes < MAX_SADDLE_ESCAPES:
                escapes += 1
                theta = theta + ESCAPE_STEP_RAD * np.sign(mode.sum() or 1.0) * mode / np.max(
                    np.abs(mode))
                continue
            reason = 'converged' + (f' after leaving {escapes} saddle(s)' if escapes else '')
            break
        if iterations >= max_iterations:
            reason = f'no convergence in {max_iterations} iterations'
            break
        if time.monotonic() > deadline:
            reason = f'no convergence within the {time_limit_s:g} s limit'
            break
        iterations += 1
        banded = planar.hessian_banded(theta, k, a, b)
        step = _newton_direction(banded, g)
        biggest = np.max(np.abs(step))
        if biggest > MAX_STEP_RAD:
            step *= MAX_STEP_RAD / biggest
        u0, slope = planar.energy(theta, k, a, b), float(g @ step)
        alpha = 1.0
        while alpha > 1e-12:
            trial = theta + alpha * step
            u = planar.energy(trial, k, a, b)
            if u <= u0 + 1e-4 * alpha * slope:
                break
            if abs(u - u0) <= 1e-13 * abs(u0) and np.max(np.abs(
                    planar.gradient(trial, k, a, b))) < np.max(np.abs(g)):
                break  # energy changes are round-off here: let the gradient decide
            alpha *= 0.5
        else:
            if residual <= 1e3 * tol:  # at the floor of round-off: as good as it gets
                reason = 'converged (at round-off)'
                break
            reason = f'line search failed (residual {residual:.3g})'
            break
        theta = trial
    converged = reason.startswith('converged')
    stability = np.nan
    if np.all(np.isfinite(theta)):
        stability, _ = _smallest_eigen(planar.hessian_banded(theta, k, a, b))
    return Equilibrium(theta, planar.points(chain, theta) if np.all(np.isfinite(theta))
                       else np.full((n + 1, 3), np.nan), converged, reason, iterations,
                       residual, stability, float(planar.energy(theta, k, a, b)))
