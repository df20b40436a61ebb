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
from tentacle_model import compiled_cache, eigen, link_loads

compiled_cache.fresh(__file__, eigen)


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
    Return the smallest eigenvalue of a symmetric tridiagonal matrix (eigen.py).

    :param diagonal: (n,) diagonal
    :param off: (n - 1,) off-diagonal
    """
    return eigen.tridiagonal_lowest(diagonal, off)


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
    moments, centres, u = _links(np.ascontiguousarray(theta, dtype=float), chain.moments_a_m2,
                                 chain.lengths_m, chain.base_rotation, chain.base_position_m)
    loads = link_loads.total(loads, moments, centres, hessian)
    if loads is None:
        n = len(theta)
        return 0.0, np.zeros(n), np.zeros((n, n)) if hessian else None
    gradient, hess = _projected(chain.lengths_m, chain.base_rotation[:, 2].copy(), moments, u,
                                loads.grad_moments, loads.grad_centres,
                                loads.hessian if hessian else np.zeros((0, 0)), hessian)
    return loads.energy_j, gradient, hess if hessian else None


@numba.njit(cache=True)
def _links(theta, local, lengths, base_rotation, base_position):
    """Return world moments, centres and directions u_i (each (n, 3)) of the links."""
    n = theta.shape[0]
    moments, centres, u = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    joint = base_position.copy()
    for i in range(n):
        c, s = np.cos(theta[i]), np.sin(theta[i])
        m0 = c * local[i, 0] - s * local[i, 1]
        m1 = s * local[i, 0] + c * local[i, 1]
        for r in range(3):
            moments[i, r] = (base_rotation[r, 0] * m0 + base_rotation[r, 1] * m1
                             + base_rotation[r, 2] * local[i, 2])
            u[i, r] = base_rotation[r, 0] * c + base_rotation[r, 1] * s
            centres[i, r] = joint[r] + 0.5 * lengths[i] * u[i, r]
            joint[r] += lengths[i] * u[i, r]
    return moments, centres, u


@numba.njit(cache=True)
def _projected(lengths, z, moments, u, grad_m, grad_c, hess_x, want_hessian):
    """
    Compiled tail of project_loads: the gradient, and J^T H_xx J plus the diagonal term.

    J is never formed: its moment rows are diagonal (z x m_i) and its centre rows lower
    triangular (h_j z x u_j for j < i, half for j = i), so a row of H_xx times J is a suffix
    sum over the links, O(n) (_times_jacobian), and the product O(n^2).
    """
    n = moments.shape[0]
    z_m, z_u = np.empty((n, 3)), np.empty((n, 3))
    for i in range(n):
        z_m[i] = _cross(z, moments[i])
        z_u[i] = _cross(z, u[i])
    lever_force = np.empty((n, 3))   # the force a joint's turn carries: links beyond, half its own
    beyond = np.zeros(3)
    for i in range(n - 1, -1, -1):
        lever_force[i] = beyond + 0.5 * grad_c[i]
        beyond += grad_c[i]
    gradient = np.empty(n)
    for i in range(n):
        gradient[i] = grad_m[i] @ z_m[i] + lengths[i] * (lever_force[i] @ z_u[i])
    hess = np.empty((n if want_hessian else 0, n if want_hessian else 0))
    if not want_hessian:
        return gradient, hess
    jt_h = np.empty((n, 6 * n))          # J^T H_xx, row by row of H_xx (it is symmetric)
    for r in range(6 * n):
        _times_jacobian(hess_x[r], lengths, z_m, z_u, jt_h[:, r])
    for i in range(n):
        _times_jacobian(jt_h[i], lengths, z_m, z_u, hess[i])
    for i in range(n):
        for k in range(i):
            hess[i, k] = hess[k, i] = 0.5 * (hess[i, k] + hess[k, i])
        # The second derivatives of m_i and c_i: z x (z x v) = -v in the plane.
        m_perp = moments[i] - (moments[i] @ z) * z
        hess[i, i] -= grad_m[i] @ m_perp + lengths[i] * (lever_force[i] @ u[i])
    return gradient, hess


@numba.njit(cache=True)
def _times_jacobian(row, lengths, z_m, z_u, out):
    """Write row (6n,) times J (6n, n) into out (n,): see _projected."""
    n = z_m.shape[0]
    b0 = b1 = b2 = 0.0                   # the row's centre entries summed over links i+1 ..
    for i in range(n - 1, -1, -1):
        m, c = 3 * i, 3 * n + 3 * i
        out[i] = (row[m] * z_m[i, 0] + row[m + 1] * z_m[i, 1] + row[m + 2] * z_m[i, 2]
                  + lengths[i] * ((b0 + 0.5 * row[c]) * z_u[i, 0]
                                  + (b1 + 0.5 * row[c + 1]) * z_u[i, 1]
                                  + (b2 + 0.5 * row[c + 2]) * z_u[i, 2]))
        b0 += row[c]
        b1 += row[c + 1]
        b2 += row[c + 2]


@numba.njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


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
