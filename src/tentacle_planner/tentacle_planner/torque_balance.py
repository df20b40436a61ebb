"""
The inverse residual for the planner: torque balance at given joint angles (planar).

Thesis eq. 6.6: at equilibrium the elastic torque at joint i balances the magnetic torques on
every link distal of it. With joint angles Q prescribed (the desired shape), the residual

    lambda_i = sum_{n >= i} tau_n(m_n, B, Q) - k_i Q_i,   tau_n = (R(theta_n) m_n x B)_z

is zero exactly when Q is an equilibrium; it is minus the energy gradient in joint
coordinates (lambda = J^T tau - K Q). The planner varies the magnetisation directions psi_n
(in the link frame, radian) and the field B = (B_x, B_y) in the base plane (tesla), so this
module returns the residual with its derivatives with respect to both, in closed form.
"""

import numpy as np


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
