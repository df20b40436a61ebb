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


def _local_rotations(q):
    """
    Return Rz(q0) Ry(q1) Rx(q2) for every joint (n, 3, 3), and Rz(q0) Ry(q1) e_x (n, 3).

    Written out (ZYX Euler angles) so a whole chain costs a few vector operations.
    """
    c0, s0 = np.cos(q[:, 0]), np.sin(q[:, 0])
    c1, s1 = np.cos(q[:, 1]), np.sin(q[:, 1])
    c2, s2 = np.cos(q[:, 2]), np.sin(q[:, 2])
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0] = c0 * c1
    r[:, 0, 1] = c0 * s1 * s2 - s0 * c2
    r[:, 0, 2] = c0 * s1 * c2 + s0 * s2
    r[:, 1, 0] = s0 * c1
    r[:, 1, 1] = s0 * s1 * s2 + c0 * c2
    r[:, 1, 2] = s0 * s1 * c2 - c0 * s2
    r[:, 2, 0] = -s1
    r[:, 2, 1] = c1 * s2
    r[:, 2, 2] = c1 * c2
    return r, np.column_stack([-s0, c0, np.zeros_like(c0)])


def kinematics(chain, q):
    """
    Return (link rotations (n, 3, 3), joint axes in the world (n, 3, 3): [joint, axis]).

    Axis 0 is the parent's z; axis 1 the parent's y turned by the first bend; axis 2 the
    link's own x.
    """
    local, y_after_bend = _local_rotations(q)
    rotations = np.empty_like(local)
    parent = chain.base_rotation
    for j in range(len(q)):
        parent = rotations[j] = parent @ local[j]
    parents = np.concatenate([chain.base_rotation[None], rotations[:-1]])
    axes = np.empty_like(local)
    axes[:, 0] = parents[:, :, 2]
    axes[:, 1] = np.einsum('nij,nj->ni', parents, y_after_bend)
    axes[:, 2] = rotations[:, :, 0]
    return rotations, axes


def gravity_levers(chain):
    """Return W_i h_i (n,), kg m: (mass distal of link i + half its own) times its length."""
    masses = chain.masses_kg
    distal_mass = np.cumsum(masses[::-1])[::-1] - masses
    return (distal_mass + masses / 2) * chain.lengths_m


class Loads:
    """What the loads contribute at one configuration: moments, levers and distal sums."""

    def __init__(self, chain, q, field_t, gravity_m_s2, levers=None):
        """
        Compute frames, world moments v_i, gravity levers w_i and their distal sums.

        :param levers: gravity_levers(chain), if the caller already has them
        """
        self.field = np.asarray(field_t, dtype=float)
        self.gravity = np.asarray(gravity_m_s2, dtype=float)
        self.rotations, self.axes = kinematics(chain, q)
        self.v = (self.rotations @ chain.moments_a_m2[:, :, None])[:, :, 0]
        self.V = np.cumsum(self.v[::-1], axis=0)[::-1]
        self.T = cross(self.V, self.field)
        self.has_gravity = bool(self.gravity.any())
        if self.has_gravity:
            levers = gravity_levers(chain) if levers is None else levers
            self.w = levers[:, None] * self.rotations[:, :, 0]
            self.W = np.cumsum(self.w[::-1], axis=0)[::-1]
            self.T += cross(self.W, self.gravity)


def energy(chain, q, loads):
    """Return the total potential energy, J."""
    u = 0.5 * float(np.sum(chain.stiffness_n_m * q * q)) - float(np.sum(loads.v @ loads.field))
    if loads.has_gravity:
        u -= float(np.sum(loads.w @ loads.gravity))
    return u


def gradient(chain, q, loads):
    """Return dU/dq (n, 3), N m."""
    return chain.stiffness_n_m * q - np.einsum('jci,ji->jc', loads.axes, loads.T)


def hessian(chain, q, loads):
    """Return the Hessian (3n, 3n) in the flattened order (joint, then bend_1, bend_2, twist)."""
    size = 3 * chain.size
    a = loads.axes.reshape(size, 3)
    joint = np.repeat(np.arange(chain.size), 3)
    V, T = loads.V[joint], loads.T[joint]
    B = loads.field
    dots = a @ a.T                                   # (a_e . a_f)
    # -(a_f x a_e) . T_e = -(a_e x T_e) . a_f; it vanishes by itself on the diagonal.
    h = -(cross(a, T) @ a.T) - np.outer(np.einsum('ij,ij->i', a, V), a @ B) \
        + dots * (V @ B)[:, None]
    if loads.has_gravity:
        W, g = loads.W[joint], loads.gravity
        h += dots * (W @ g)[:, None] - np.outer(np.einsum('ij,ij->i', a, W), a @ g)
    upper = _upper_indices(size)
    h[upper] = h.T[upper]  # the formula holds for f <= e: mirror the lower triangle
    h.flat[::size + 1] += chain.stiffness_n_m.reshape(-1)
    return h


_UPPER = {}


def _upper_indices(size):
    """Return (and remember) the strict upper-triangle indices of a size x size matrix."""
    if size not in _UPPER:
        _UPPER[size] = np.triu_indices(size, 1)
    return _UPPER[size]


def points(chain, rotations):
    """Return the joint positions and the tip, (n + 1, 3), m, base first."""
    steps = chain.lengths_m[:, None] * rotations[:, :, 0]
    return chain.base_position_m + np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])
