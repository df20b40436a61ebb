"""
Planar (1-DoF joints) potential energy of a chain, its gradient and its banded Hessian.

Coordinates: theta (n,), the absolute angle of each link in the base plane, radian, measured
from the insertion direction (joint angles are q_i = theta_i - theta_{i-1}, theta_{-1} = 0).
In these coordinates the elastic energy is tridiagonal and every load is diagonal, so a Newton
step costs O(n).

A uniform field exerts only a torque on a link; the energy of link i, -m_i . B, and the
gravitational energy of everything distal of it (its moment arm) both have the form
-(a_i cos theta_i + b_i sin theta_i):

    U(theta) = 1/2 sum_i k_i (theta_i - theta_{i-1})^2 - sum_i (a_i cos theta_i + b_i sin theta_i)

with a_i = m_x B_x + m_y B_y + W_i h_i g_x and b_i = m_x B_y - m_y B_x + W_i h_i g_y, where
(m_x, m_y) is the moment in the link frame, B and g are projected on the base plane and
W_i = (mass distal of link i) + (half of link i's mass).
"""

import numba
import numpy as np
from tentacle_model import link_loads


def loads(chain, field_t, gravity_m_s2=(0.0, 0.0, 0.0)):
    """
    Return (a, b), each (n,), in N m: the load coefficients in the base plane.

    :param field_t: (3,) uniform field in the world frame, tesla
    :param gravity_m_s2: (3,) gravitational acceleration in the world frame
    """
    axes = chain.base_rotation[:, :2]  # base plane: insertion direction, normal
    bx, by = axes.T @ np.asarray(field_t, dtype=float)
    gx, gy = axes.T @ np.asarray(gravity_m_s2, dtype=float)
    mx, my = chain.moments_a_m2[:, 0], chain.moments_a_m2[:, 1]
    masses = chain.masses_kg
    distal = np.cumsum(masses[::-1])[::-1] - masses  # mass beyond each link
    lever = (distal + masses / 2) * chain.lengths_m
    return mx * bx + my * by + lever * gx, mx * by - my * bx + lever * gy


def joint_angles(theta):
    """Return q_i = theta_i - theta_{i-1} (n,), rad (np.diff with prepend costs 10x more)."""
    q = theta.copy()
    q[1:] -= theta[:-1]
    return q


@numba.njit(cache=True)
def evaluate(theta, k, a, b, linear, derivatives):
    """
    Return (energy J, dU/dtheta (n,) N m, Hessian in upper banded form (2, n)) in one pass.

    The banded form is scipy.linalg.solveh_banded's: row 1 the diagonal, row 0 (from column
    1) the superdiagonal. linear: the small-angle model, sin t ~ t and cos t ~ 1 - t^2 / 2.
    Without derivatives the gradient and Hessian are left zero. Every argument is passed:
    numba's fast dispatch does not cover omitted defaults (they cost 20 us a call).
    """
    n = len(theta)
    energy = 0.0
    grad = np.zeros(n)
    banded = np.zeros((2, n))
    previous = 0.0
    for i in range(n):
        t = theta[i]
        dq = t - previous
        previous = t
        energy += 0.5 * k[i] * dq * dq
        if linear:
            energy -= a[i] * (1.0 - 0.5 * t * t) + b[i] * t
        else:
            c, s = np.cos(t), np.sin(t)
            energy -= a[i] * c + b[i] * s
        if not derivatives:
            continue
        torque = k[i] * dq  # elastic torque at joint i: acts on links i and i - 1
        grad[i] += torque
        banded[1, i] += k[i]
        if i > 0:
            grad[i - 1] -= torque
            banded[1, i - 1] += k[i]
            banded[0, i] = -k[i]
        if linear:
            grad[i] += a[i] * t - b[i]
            banded[1, i] += a[i]
        else:
            grad[i] += a[i] * s - b[i] * c
            banded[1, i] += a[i] * c + b[i] * s
    return energy, grad, banded


@numba.njit(cache=True)
def smallest_eigenvalue(diagonal, off):
    """
    Return the smallest eigenvalue of a symmetric tridiagonal matrix, by bisection.

    Sturm count: the number of eigenvalues below x is the number of negative pivots of
    T - x I. Sixty halvings of the Gershgorin interval reach round-off (about 1e-16 of the
    matrix's norm, as LAPACK does) at O(n) each, where scipy's eigh_tridiagonal spends some
    40 us in its wrappers on a chain of a few links.

    :param diagonal: (n,) diagonal
    :param off: (n - 1,) off-diagonal
    """
    n = len(diagonal)
    lo, hi = np.inf, -np.inf
    for i in range(n):
        radius = (abs(off[i - 1]) if i > 0 else 0.0) + (abs(off[i]) if i < n - 1 else 0.0)
        lo = min(lo, diagonal[i] - radius)
        hi = max(hi, diagonal[i] + radius)
    tiny = 1e-300 + 1e-30 * max(abs(lo), abs(hi))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        pivot, below = 1.0, 0
        for i in range(n):
            pivot = diagonal[i] - mid - (off[i - 1] ** 2 / pivot if i > 0 else 0.0)
            if pivot == 0.0:
                pivot = -tiny  # a zero pivot: count x itself as above the eigenvalue
            if pivot < 0.0:
                below += 1
        if below >= 1:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def energy(theta, k, a, b):
    """Return the total potential energy, J."""
    return evaluate(theta, k, a, b, False, False)[0]


def gradient(theta, k, a, b):
    """Return dU/dtheta (n,), N m."""
    return evaluate(theta, k, a, b, False, True)[1]


def hessian_banded(theta, k, a, b):
    """Return the Hessian in upper banded form (2, n) (see evaluate)."""
    return evaluate(theta, k, a, b, False, True)[2]


def hessian_dense(theta, k, a, b, linear=False):
    """Return the Hessian as a dense (n, n) array (for tests and small chains)."""
    banded = evaluate(theta, k, a, b, linear, True)[2]
    return np.diag(banded[1]) + np.diag(banded[0, 1:], 1) + np.diag(banded[0, 1:], -1)


def points(chain, theta):
    """Return the joint positions and the tip, (n + 1, 3), m, base first."""
    steps = chain.lengths_m[:, None] * np.column_stack([np.cos(theta), np.sin(theta)])
    planar = np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])
    return chain.base_position_m + planar @ chain.base_rotation[:, :2].T


def project_loads(chain, theta, loads, hessian=True):
    """
    Return (energy J, gradient (n,) N m, Hessian (n, n) or None) of world-frame link loads.

    Link i's world moment is R_base Rz(theta_i) m_i and its centre
    c_i = sum_{j<i} h_j u_j + h_i u_i / 2 with u_j = R_base (cos theta_j, sin theta_j, 0), so
    with z the base plane's normal, d m_i / d theta_i = z x m_i and d c_i / d theta_j =
    h_j z x u_j (half of it for j = i); both second derivatives are diagonal in theta
    (z x (z x v) = -v in the plane), and the Hessian is J^T H_xx J plus that diagonal.

    :param loads: link_loads.py callables, e.g. link_loads.of_chain(chain, dipoles=True)
    :raises dipoles.Contact: two interacting magnets closer than they may come
    """
    n = len(theta)
    c, s = np.cos(theta), np.sin(theta)
    local = chain.moments_a_m2
    in_plane = np.column_stack([c * local[:, 0] - s * local[:, 1],
                                s * local[:, 0] + c * local[:, 1], np.zeros(n)])
    base = chain.base_rotation
    moments = (in_plane + local[:, 2:] * [0.0, 0.0, 1.0]) @ base.T
    u = np.column_stack([c, s, np.zeros(n)]) @ base.T
    steps = chain.lengths_m[:, None] * u
    joints = np.vstack([np.zeros(3), np.cumsum(steps, axis=0)[:-1]])
    centres = chain.base_position_m + joints + 0.5 * steps
    loads = link_loads.total(loads, moments, centres, hessian)
    if loads is None:
        return 0.0, np.zeros(n), np.zeros((n, n)) if hessian else None
    z = base[:, 2]
    z_m, z_u = np.cross(z, moments), np.cross(z, u)
    g, f = loads.grad_moments, loads.grad_centres
    # Force sums over the links a joint's turn carries: all beyond it, half of its own.
    lever_force = np.cumsum(f[::-1], axis=0)[::-1] - 0.5 * f
    gradient = np.sum(g * z_m, axis=1) + chain.lengths_m * np.sum(lever_force * z_u, axis=1)
    if not hessian:
        return loads.energy_j, gradient, None
    weight = np.tril(np.broadcast_to(chain.lengths_m, (n, n)), -1) + np.diag(
        0.5 * chain.lengths_m)                                     # [link i, angle j]
    jac = np.zeros((6 * n, n))
    jac[:3 * n] = (np.eye(n)[:, None, :] * z_m[:, :, None]).reshape(3 * n, n)
    jac[3 * n:] = (weight[:, None, :] * z_u.T[None, :, :]).reshape(3 * n, n)
    m_perp = moments - np.outer(moments @ z, z)
    diagonal = -np.sum(g * m_perp, axis=1) - chain.lengths_m * np.sum(lever_force * u, axis=1)
    return loads.energy_j, gradient, jac.T @ loads.hessian @ jac + np.diag(diagonal)


# -- linearised small-angle model: sin t ~ t, cos t ~ 1 - t^2 / 2 in loads and kinematics ----
def energy_linear(theta, k, a, b):
    """Return the small-angle energy, J (quadratic in theta)."""
    return evaluate(theta, k, a, b, True, False)[0]


def gradient_linear(theta, k, a, b):
    """Return the small-angle dU/dtheta (n,), N m."""
    return evaluate(theta, k, a, b, True, True)[1]


def points_linear(chain, theta):
    """Return small-angle joint positions and tip, (n + 1, 3): x = sum h, y = sum h theta."""
    steps = chain.lengths_m[:, None] * np.column_stack([np.ones_like(theta), theta])
    planar = np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])
    return chain.base_position_m + planar @ chain.base_rotation[:, :2].T
