"""
An independent reference: the hard-magnetic elastica of a uniformly magnetised cantilever.

E I theta'' + M A B sin(phi - theta) = 0 with theta(0) = 0 and theta'(L) = 0 (clamped base,
free tip; the magnetisation along the rod, the field at phi to the clamp's direction), solved
as a boundary-value problem with scipy, independently of the chain model. Tests and benches
check the model and the simulated rig against it.
"""

import numpy as np


def cantilever_tip(length_m, ei_n_m2, ma_a_m, field_t, field_angle_deg):
    """
    Return the tip (x, y), m, in the clamp's frame (x along the clamp, y towards the field).

    :param length_m: the free length, m
    :param ei_n_m2: bending stiffness, N m^2
    :param ma_a_m: magnetisation times section area, A m
    :param field_t: field magnitude, T
    :param field_angle_deg: the field's angle from the clamp's direction, deg (0-180)
    :raises RuntimeError: the boundary-value solver did not converge
    """
    from scipy.integrate import solve_bvp
    phi, c = np.radians(field_angle_deg), ma_a_m * field_t / ei_n_m2

    def rhs(s, y):
        return np.vstack([y[1], -c * np.sin(phi - y[0]), np.cos(y[0]), np.sin(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    s = np.linspace(0, length_m, 400)
    bend = 1.5 * np.sin(np.pi * s / (2 * length_m))  # a buckled guess, bending towards +y
    guess = np.vstack([bend, np.gradient(bend, s), s, np.zeros_like(s)])
    solution = solve_bvp(rhs, bc, s, guess, tol=1e-8, max_nodes=200000)
    if solution.status != 0:
        raise RuntimeError(f'elastica did not converge: {solution.message}')
    return solution.y[2:, -1]
