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
"""

import numpy as np


def cross(a, b):
    """Return row-wise cross products of (..., 3) arrays (numpy's cross is slow for small ones)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _rotations(angles, axis):
    """Return elementary rotation matrices (n, 3, 3) about a fixed axis index."""
    c, s = np.cos(angles), np.sin(angles)
    r = np.zeros((len(angles), 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]  # the plane each rotation turns
    r[:, axis, axis] = 1.0
    r[:, i, i] = c
    r[:, j, j] = c
    r[:, j, i] = s
    r[:, i, j] = -s
    return r


def kinematics(chain, q):
    """Return (link rotations (n, 3, 3), joint axes in the world (n, 3, 3): [joint, axis])."""
    n = chain.size
    rz, ry, rx = _rotations(q[:, 0], 2), _rotations(q[:, 1], 1), _rotations(q[:, 2], 0)
    rotations = np.empty((n, 3, 3))
    axes = np.empty((n, 3, 3))
    parent = chain.base_rotation
    for j in range(n):
        axes[j, 0] = parent[:, 2]
        after_z = parent @ rz[j]
        axes[j, 1] = after_z[:, 1]
        after_y = after_z @ ry[j]
        axes[j, 2] = after_y[:, 0]
        parent = rotations[j] = after_y @ rx[j]
    return rotations, axes


class Loads:
    """What the loads contribute at one configuration: moments, levers and distal sums."""

    def __init__(self, chain, q, field_t, gravity_m_s2):
        """Compute frames, world moments v_i, gravity levers w_i and their distal sums."""
        self.field = np.asarray(field_t, dtype=float)
        self.gravity = np.asarray(gravity_m_s2, dtype=float)
        self.rotations, self.axes = kinematics(chain, q)
        masses = chain.masses_kg
        distal_mass = np.cumsum(masses[::-1])[::-1] - masses
        lever = (distal_mass + masses / 2) * chain.lengths_m
        self.v = np.einsum('nij,nj->ni', self.rotations, chain.moments_a_m2)
        self.w = lever[:, None] * self.rotations[:, :, 0]
        self.V = np.cumsum(self.v[::-1], axis=0)[::-1]
        self.W = np.cumsum(self.w[::-1], axis=0)[::-1]
        self.T = cross(self.V, self.field) + cross(self.W, self.gravity)


def energy(chain, q, loads):
    """Return the total potential energy, J."""
    k = chain.stiffness_n_m
    return 0.5 * np.sum(k * q * q) - np.sum(loads.v @ loads.field) - np.sum(
        loads.w @ loads.gravity)


def gradient(chain, q, loads):
    """Return dU/dq (n, 3), N m."""
    return chain.stiffness_n_m * q - np.einsum('jci,ji->jc', loads.axes, loads.T)


def hessian(chain, q, loads):
    """Return the Hessian (3n, 3n) in the flattened order (joint, then bend_1, bend_2, twist)."""
    n = chain.size
    a = loads.axes.reshape(3 * n, 3)
    joint = np.repeat(np.arange(n), 3)
    V, W, T = loads.V[joint], loads.W[joint], loads.T[joint]
    B, g = loads.field, loads.gravity
    dots = a @ a.T                                   # (a_e . a_f)
    # -(a_f x a_e) . T_e = -(a_e x T_e) . a_f; it vanishes by itself on the diagonal.
    h = (-cross(a, T) @ a.T
         - np.outer(np.sum(a * V, axis=1), a @ B) + dots * (V @ B)[:, None]
         - np.outer(np.sum(a * W, axis=1), a @ g) + dots * (W @ g)[:, None])
    upper = np.triu_indices(3 * n, 1)
    h[upper] = h.T[upper]  # the formula holds for f <= e: mirror the lower triangle
    h[np.diag_indices(3 * n)] += chain.stiffness_n_m.reshape(-1)
    return h


def points(chain, rotations):
    """Return the joint positions and the tip, (n + 1, 3), m, base first."""
    steps = chain.lengths_m[:, None] * rotations[:, :, 0]
    return chain.base_position_m + np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])
