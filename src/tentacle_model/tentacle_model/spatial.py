"""
3-DoF joints (bend, bend, twist): potential energy, gradient and Hessian of a chain.

Coordinates: q (n, 3), per joint the angles of three elementary rotations about the parent
link's axes, in order: bend_1 about z (in the base plane), bend_2 about the new y (out of
it), twist about the new x (the link axis). R_i = R_{i-1} Rz(q_i0) Ry(q_i1) Rx(q_i2), and the
joint stiffness is diagonal in these angles, K = diag(k_bend_1, k_bend_2, k_twist).

The chain is then a serial manipulator with 3n revolute axes a_e (world frame), and the
classic closed forms apply. With V_J and W_J the magnetic moments and gravity levers of all
links distal of joint J (world frame) and T_J = V_J x B + W_J x g their torque,

    U = 1/2 q.K.q - sum_i (R_i m_i . B + W_i h_i R_i x . g)
    dU/dq_e = k_e q_e - a_e . T_J(e)
    d2U/dq_e dq_f (f <= e) = k_e [e = f] - [f < e] (a_f x a_e) . T_J(e)
                             - (a_e . V)(a_f . B) + (a_e . a_f)(V . B)
                             - (a_e . W)(a_f . g) + (a_e . a_f)(W . g),   V, W at J(e)

since an axis turns with every earlier angle (d a_e / d q_f = a_f x a_e) and every distal
vector too (d v / d q_f = a_f x v).

Kinematics, energy, gradient and Hessian are one compiled pass (numba): a Newton iteration
of a 5-link chain is tens of microseconds, where the same maths as numpy calls on (n, 3)
arrays spent a quarter of a millisecond in call overhead (bench/model_tradeoff.py).
"""

from dataclasses import dataclass

import numba
import numpy as np
from tentacle_model import link_loads


def cross(a, b):
    """Return row-wise cross products of (..., 3) arrays (numpy's cross is slow for small ones)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def gravity_levers(chain):
    """Return W_i h_i (n,), kg m: (mass distal of link i + half its own) times its length."""
    masses = chain.masses_kg
    distal_mass = np.cumsum(masses[::-1])[::-1] - masses
    return (distal_mass + masses / 2) * chain.lengths_m


@dataclass(frozen=True)
class Evaluation:
    """The chain at one configuration q (n, 3); world frame, SI units."""

    rotations: np.ndarray       # (n, 3, 3) link frames
    axes: np.ndarray            # (n, 3, 3) joint axes [joint, bend_1 / bend_2 / twist, xyz]
    points_m: np.ndarray        # (n + 1, 3) joints and tip, base first
    energy_j: float
    gradient: np.ndarray        # (n, 3) dU/dq, N m
    hessian: np.ndarray         # (3n, 3n), N m / rad^2, flattened (joint, angle); or None
    distal_moments: np.ndarray  # (n, 3) V_J, A m^2
    torques: np.ndarray         # (n, 3) T_J = V_J x B + W_J x g, N m
    largest_torque_n_m: float   # max over joints of |T_J| and of the elastic |k q|


def evaluate(chain, q, field_t, gravity_m_s2=(0.0, 0.0, 0.0), hessian=True, levers=None,
             loads=()):
    """
    Return the Evaluation of a chain at joint angles q (n, 3), rad.

    :param field_t: (3,) uniform field, tesla, world frame
    :param gravity_m_s2: (3,) gravity, world frame
    :param hessian: also the Hessian (the dominant cost past a few tens of links)
    :param levers: gravity_levers(chain), if the caller already has them
    :param loads: world-frame link loads (link_loads.py), e.g. link_loads.of_chain(chain,
        dipoles=True); () for the uniform field and gravity alone
    :raises dipoles.Contact: two interacting magnets closer than they may come
    """
    levers = gravity_levers(chain) if levers is None else levers
    out = _evaluate(np.ascontiguousarray(q, dtype=float), chain.base_rotation,
                    chain.base_position_m, chain.lengths_m, chain.moments_a_m2, levers,
                    chain.stiffness_n_m, np.asarray(field_t, dtype=float),
                    np.asarray(gravity_m_s2, dtype=float), hessian)
    rotations, axes, points_m, energy_j, grad, hess, distal, torques, largest = out
    if loads:
        moments = (rotations @ chain.moments_a_m2[:, :, None])[:, :, 0]
        centres = points_m[:-1] + 0.5 * chain.lengths_m[:, None] * rotations[:, :, 0]
        extra = link_loads.total(loads, moments, centres, hessian)
        d_grad, d_hess = _project_link_loads(axes, points_m[:-1], moments, centres, extra,
                                             hessian)
        energy_j += extra.energy_j
        grad = grad + d_grad
        if hessian:
            hess = hess + d_hess
    return Evaluation(rotations, axes, points_m, energy_j, grad, hess if hessian else None,
                      distal, torques, largest)


def _project_link_loads(axes, joints, moments, centres, loads, hessian):
    """
    Return (gradient (n, 3), Hessian (3n, 3n) or None) in joint angles of a link energy.

    loads (a dipoles.Interaction) gives the energy's derivatives with respect to each link's
    world moment m_i and centre c_i: G_i, F_i and their Hessian H_xx. With the Jacobian
    J = d(m, c)/dq (d m_i / d q_e = a_e x m_i, d c_i / d q_e = a_e x (c_i - o_e) for links
    distal of joint J(e) at o_e), the Hessian is J^T H_xx J plus, for f <= e,
    a_f . (a_e x S1_e + S2_e a_e) - (a_f . a_e) s3_e with distal sums over i >= J(e) of
    S1 = m_i x G_i + d_i x F_i, S2 = G_i m_i^T + F_i d_i^T, s3 = G_i . m_i + F_i . d_i,
    d_i = c_i - o_e (the second derivatives of m_i and c_i, as in the module docstring).
    """
    empty = np.zeros((0, 0))
    return _projected(axes, joints, moments, centres, loads.grad_moments, loads.grad_centres,
                      loads.hessian if hessian else empty, hessian)


@numba.njit(cache=True)
def _projected(axes, joints, moments, centres, grad_m, grad_c, hess_x, want_hessian):
    """
    Return _project_link_loads' answer, compiled and without forming J.

    A row h of H_xx times J's column e is
    sum over i >= J(e) of h_mi . (a_e x m_i) + h_ci . (a_e x (c_i - o_e))
    = a_e . (sum_i (m_i x h_mi + c_i x h_ci) - o_e x sum_i h_ci): suffix sums over the links,
    so J^T H_xx J costs O(n^2) (a dense product with J, O(n^3), took 17 ms at 128 links).
    """
    n = moments.shape[0]
    size = 3 * n
    s1 = np.empty((n, 3))        # the docstring's sums, joint by joint
    s2 = np.empty((n, 3, 3))
    s3 = np.empty(n)
    acc1, acc_f, acc2, acc3 = np.zeros(3), np.zeros(3), np.zeros((3, 3)), 0.0
    for i in range(n - 1, -1, -1):
        m, c, g, f, o = moments[i], centres[i], grad_m[i], grad_c[i], joints[i]
        acc1 += _cross(m, g) + _cross(c, f)
        acc_f += f
        for r in range(3):
            for k in range(3):
                acc2[r, k] += g[r] * m[k] + f[r] * c[k]
        acc3 += m[0] * g[0] + m[1] * g[1] + m[2] * g[2] + c[0] * f[0] + c[1] * f[1] + c[2] * f[2]
        s1[i] = acc1 - _cross(o, acc_f)
        for r in range(3):
            for k in range(3):
                s2[i, r, k] = acc2[r, k] - acc_f[r] * o[k]
        s3[i] = acc3 - (o[0] * acc_f[0] + o[1] * acc_f[1] + o[2] * acc_f[2])
    gradient = np.empty((n, 3))
    for i in range(n):
        for k in range(3):
            a = axes[i, k]
            gradient[i, k] = a[0] * s1[i, 0] + a[1] * s1[i, 1] + a[2] * s1[i, 2]
    hess = np.empty((size if want_hessian else 0, size if want_hessian else 0))
    if not want_hessian:
        return gradient, hess
    jt_h = np.empty((size, 6 * n))          # J^T H_xx, row by row of H_xx (it is symmetric)
    for r in range(6 * n):
        _times_jacobian(hess_x[r], axes, joints, moments, centres, jt_h[:, r])
    for e in range(size):                   # (J^T H_xx) J, row by row
        _times_jacobian(jt_h[e], axes, joints, moments, centres, hess[e])
    for e in range(size):                   # exactly symmetric, as eigh and Cholesky assume
        for f in range(e):
            hess[e, f] = hess[f, e] = 0.5 * (hess[e, f] + hess[f, e])
    for e in range(size):
        i = e // 3
        ae = axes[i, e % 3]
        w = _cross(ae, s1[i]) + s2[i] @ ae
        for f in range(e + 1):
            af = axes[f // 3, f % 3]
            value = (af[0] * w[0] + af[1] * w[1] + af[2] * w[2]
                     - (ae[0] * af[0] + ae[1] * af[1] + ae[2] * af[2]) * s3[i])
            hess[e, f] += value
            if f != e:
                hess[f, e] += value
    return gradient, hess


@numba.njit(cache=True)
def _times_jacobian(row, axes, joints, moments, centres, out):
    """Write row (6n,) times J (6n, 3n) into out (3n,): see _projected."""
    n = moments.shape[0]
    u0 = u1 = u2 = w0 = w1 = w2 = 0.0
    for i in range(n - 1, -1, -1):
        m, c, o = moments[i], centres[i], joints[i]
        hm0, hm1, hm2 = row[3 * i], row[3 * i + 1], row[3 * i + 2]
        hc0, hc1, hc2 = row[3 * n + 3 * i], row[3 * n + 3 * i + 1], row[3 * n + 3 * i + 2]
        u0 += m[1] * hm2 - m[2] * hm1 + c[1] * hc2 - c[2] * hc1
        u1 += m[2] * hm0 - m[0] * hm2 + c[2] * hc0 - c[0] * hc2
        u2 += m[0] * hm1 - m[1] * hm0 + c[0] * hc1 - c[1] * hc0
        w0 += hc0
        w1 += hc1
        w2 += hc2
        v0 = u0 - (o[1] * w2 - o[2] * w1)
        v1 = u1 - (o[2] * w0 - o[0] * w2)
        v2 = u2 - (o[0] * w1 - o[1] * w0)
        for k in range(3):
            a = axes[i, k]
            out[3 * i + k] = a[0] * v0 + a[1] * v1 + a[2] * v2


@numba.njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def points_linear(chain, q):
    """
    Return joint positions and tip (n + 1, 3), m, with kinematics linearised about q = 0.

    At q = 0 every joint's axes are the base frame's z, y and x, so link i is turned by the
    small rotation vector phi_i = sum over joints j <= i of (q_j2, q_j1, q_j0) (base frame)
    and its direction is e_x + phi_i x e_x = (1, phi_z, -phi_y).
    """
    phi = np.cumsum(np.asarray(q, dtype=float), axis=0)
    directions = np.column_stack([np.ones(len(phi)), phi[:, 0], -phi[:, 1]])
    steps = chain.lengths_m[:, None] * (directions @ chain.base_rotation.T)
    return chain.base_position_m + np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])


@numba.njit(cache=True)
def _evaluate(q, base_rotation, base_position, lengths, moments, levers, stiffness, field,
              gravity, want_hessian):
    """Compiled pass over the chain: see Evaluation and the module docstring."""
    n = q.shape[0]
    rotations = np.empty((n, 3, 3))
    axes = np.empty((n, 3, 3))
    points = np.empty((n + 1, 3))
    # the temporaries in one allocation (a batch evaluates a 5-link chain in under a microsecond,
    # and an allocation is some 40 ns of it)
    frames = np.empty((2, 3, 3))
    parent, local = frames[0], frames[1]
    parent[:] = base_rotation
    sums = np.empty((3, n, 3))
    v, w, distal_w = sums[0], sums[1], sums[2]
    points[0] = base_position
    energy = 0.0
    for i in range(n):
        c0, s0 = np.cos(q[i, 0]), np.sin(q[i, 0])
        c1, s1 = np.cos(q[i, 1]), np.sin(q[i, 1])
        c2, s2 = np.cos(q[i, 2]), np.sin(q[i, 2])
        # Rz(q0) Ry(q1) Rx(q2), written out.
        local[0, 0] = c0 * c1
        local[0, 1] = c0 * s1 * s2 - s0 * c2
        local[0, 2] = c0 * s1 * c2 + s0 * s2
        local[1, 0] = s0 * c1
        local[1, 1] = s0 * s1 * s2 + c0 * c2
        local[1, 2] = s0 * s1 * c2 - c0 * s2
        local[2, 0] = -s1
        local[2, 1] = c1 * s2
        local[2, 2] = c1 * c2
        for r in range(3):
            axes[i, 0, r] = parent[r, 2]
            axes[i, 1, r] = c0 * parent[r, 1] - s0 * parent[r, 0]
            for c in range(3):
                rotations[i, r, c] = (parent[r, 0] * local[0, c] + parent[r, 1] * local[1, c]
                                      + parent[r, 2] * local[2, c])
        for r in range(3):
            axes[i, 2, r] = rotations[i, r, 0]
            points[i + 1, r] = points[i, r] + lengths[i] * rotations[i, r, 0]
            v[i, r] = (rotations[i, r, 0] * moments[i, 0] + rotations[i, r, 1] * moments[i, 1]
                       + rotations[i, r, 2] * moments[i, 2])
            w[i, r] = levers[i] * rotations[i, r, 0]
            energy -= v[i, r] * field[r] + w[i, r] * gravity[r]
            for c in range(3):
                parent[r, c] = rotations[i, r, c]
        for c in range(3):
            energy += 0.5 * stiffness[i, c] * q[i, c] * q[i, c]
    # Distal sums from the tip, and the load torque at each joint.
    distal_v = np.empty((n, 3))
    torques = np.empty((n, 3))
    for i in range(n - 1, -1, -1):
        for r in range(3):
            distal_v[i, r] = v[i, r] + (distal_v[i + 1, r] if i + 1 < n else 0.0)
            distal_w[i, r] = w[i, r] + (distal_w[i + 1, r] if i + 1 < n else 0.0)
        V, W = distal_v[i], distal_w[i]
        torques[i, 0] = V[1] * field[2] - V[2] * field[1] + W[1] * gravity[2] - W[2] * gravity[1]
        torques[i, 1] = V[2] * field[0] - V[0] * field[2] + W[2] * gravity[0] - W[0] * gravity[2]
        torques[i, 2] = V[0] * field[1] - V[1] * field[0] + W[0] * gravity[1] - W[1] * gravity[0]
    grad = np.empty((n, 3))
    largest = 0.0
    for i in range(n):
        T = torques[i]
        largest = max(largest, np.sqrt(T[0] * T[0] + T[1] * T[1] + T[2] * T[2]))
        for c in range(3):
            largest = max(largest, abs(stiffness[i, c] * q[i, c]))
            a = axes[i, c]
            grad[i, c] = stiffness[i, c] * q[i, c] - (a[0] * torques[i, 0] + a[1] * torques[i, 1]
                                                      + a[2] * torques[i, 2])
    size = 3 * n if want_hessian else 0
    hess = np.empty((size, size))
    if want_hessian:
        a = axes.reshape(size, 3)
        a_loads = np.empty((2, size))
        a_field, a_gravity = a_loads[0], a_loads[1]
        for e in range(size):
            a_field[e] = a[e, 0] * field[0] + a[e, 1] * field[1] + a[e, 2] * field[2]
            a_gravity[e] = a[e, 0] * gravity[0] + a[e, 1] * gravity[1] + a[e, 2] * gravity[2]
        for e in range(size):
            j = e // 3
            ae, V, W, T = a[e], distal_v[j], distal_w[j], torques[j]
            u0 = ae[1] * T[2] - ae[2] * T[1]    # a_e x T_e
            u1 = ae[2] * T[0] - ae[0] * T[2]
            u2 = ae[0] * T[1] - ae[1] * T[0]
            alpha = ae[0] * V[0] + ae[1] * V[1] + ae[2] * V[2]
            gamma = ae[0] * W[0] + ae[1] * W[1] + ae[2] * W[2]
            beta = (V[0] * field[0] + V[1] * field[1] + V[2] * field[2]
                    + W[0] * gravity[0] + W[1] * gravity[1] + W[2] * gravity[2])
            for f in range(e + 1):
                af = a[f]
                value = (-(u0 * af[0] + u1 * af[1] + u2 * af[2]) - alpha * a_field[f]
                         - gamma * a_gravity[f]
                         + (ae[0] * af[0] + ae[1] * af[1] + ae[2] * af[2]) * beta)
                hess[e, f] = value
                hess[f, e] = value
            hess[e, e] += stiffness[j, e % 3]
    return rotations, axes, points, energy, grad, hess, distal_v, torques, largest
