"""
The inverse residual for the planner: torque balance at given joint angles.

Thesis eq. 6.6: at equilibrium the elastic torque at joint i balances the magnetic torques on
every link distal of it. With joint angles Q prescribed (the desired shape), the residual

    lambda_i = sum_{n >= i} tau_n(m_n, B, Q) - k_i Q_i,   tau_n = (R(theta_n) m_n x B)_z

is zero exactly when Q is an equilibrium; it is minus the energy gradient in joint
coordinates (lambda = J^T tau - K Q). The planner varies the magnetisation directions psi_n
(in the link frame, radian) and the field B = (B_x, B_y) in the base plane (tesla), so this
module returns the residual with its derivatives with respect to both, in closed form;
residual_3dof does the same for bend-bend-twist joints (thesis eq. 5.2).
"""

import numpy as np
from tentacle_model import spatial


def residual(joint_angles_rad, stiffness_n_m, moment_a_m2, psi_rad, field_t):
    """
    Return (lambda (n,), d lambda / d psi (n, n), d lambda / d B (n, 2)), N m.

    :param joint_angles_rad: (n,) prescribed joint angles Q, base first
    :param stiffness_n_m: (n,) joint stiffness k, N m / rad
    :param moment_a_m2: (n,) magnitude of each link's magnetic moment, A m^2
    :param psi_rad: (n,) magnetisation direction of each link in its own frame, rad
    :param field_t: (2,) field in the base plane, tesla
    """
    q = np.asarray(joint_angles_rad, dtype=float)
    mu = np.asarray(moment_a_m2, dtype=float)
    bx, by = np.asarray(field_t, dtype=float)
    direction = np.cumsum(q) + np.asarray(psi_rad, dtype=float)  # moment angle, base frame
    cos, sin = np.cos(direction), np.sin(direction)
    tau = mu * (cos * by - sin * bx)
    distal = np.triu(np.ones((len(q), len(q))))  # row i sums links n >= i
    lam = distal @ tau - np.asarray(stiffness_n_m, dtype=float) * q
    dtau_dpsi = -mu * (cos * bx + sin * by)      # = -(m . B)
    dtau_db = np.column_stack([-mu * sin, mu * cos])
    return lam, distal * dtau_dpsi[None, :], distal @ dtau_db


def residual_3dof(chain, joint_angles_rad, field_t, gravity_m_s2=(0.0, 0.0, 0.0)):
    """
    Return the 3-DoF torque balance and its derivatives at prescribed joint angles.

    lambda_e = a_e . T_J(e) - k_e q_e for every elementary joint e (bend_1, bend_2, twist of
    each joint), i.e. minus the energy gradient (spatial.py). The planner varies the field
    and the magnetic moments, so the derivatives are taken with respect to B (world frame)
    and to each link's moment vector in its own frame (A m^2); a parameterisation of the
    directions (angles, unit vectors) chains onto the latter.

    :param chain: a Chain; its moments_a_m2 are the moments the residual is evaluated at
    :param joint_angles_rad: (n, 3) prescribed joint angles Q
    :param field_t: (3,) uniform field, tesla
    :param gravity_m_s2: (3,) gravity, world frame (it enters lambda, not the derivatives)
    :return: (lambda (n, 3) N m, d lambda / d B (n, 3, 3) N m / T,
        d lambda / d m (n, 3, n, 3) N m / (A m^2): [joint, angle, link, component])
    """
    q = np.asarray(joint_angles_rad, dtype=float)
    b = np.asarray(field_t, dtype=float)
    state = spatial.evaluate(chain, q, b, gravity_m_s2, hessian=False)
    lam = -state.gradient
    # a . (V x B) = B . (a x V): linear in B.
    d_field = spatial.cross(state.axes, state.distal_moments[:, None, :])
    # a . (R_i m_i x B) = m_i . R_i^T (B x a): only links distal of the joint count.
    b_cross_a = spatial.cross(np.broadcast_to(b, state.axes.shape), state.axes)
    n = chain.size
    d_moment = np.einsum('ikl,jck->jcil', state.rotations, b_cross_a)
    distal = np.arange(n)[None, :] >= np.arange(n)[:, None]      # [joint j, link i]: i >= j
    d_moment *= distal[:, None, :, None]
    return lam, d_field, d_moment
