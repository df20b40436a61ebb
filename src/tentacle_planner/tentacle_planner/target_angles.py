"""
Joint angles that lay a chain along its follow-the-leader target, twist by least strain energy.

A centreline fixes each link's direction but not its roll about it: with 3-DoF joints
(R_i = R_{i-1} Rz(q_i0) Ry(q_i1) Rx(q_i2), tentacle_model.spatial) n rolls are free. As in
thesis 5.3.1 they are chosen to minimise the strain energy 1/2 q.K.q, K = chain.stiffness_n_m
per joint: an isotropic tentacle then twists hardly at all, a flat strip may roll into its
soft plane.

Directions: each link points from where the chain's previous joint is towards the next target
point (paths.targets). Where consecutive targets are a link length apart (a path the model can
lie along exactly, such as one it made) every joint lands on its target. On a curve they are
closer (a chord is shorter than its arc, by about h^3 / (24 R^2) for a link of length h on a
radius R): there the chain runs ahead of its targets by the shortfalls so far, keeping close to
the path (it is turned off it only by the chord's angle to the tangent).

The minimisation: let F_i be the frame carried along the link directions by the smallest
rotation from link to link (F_-1 the base frame, so c_i = F_{i-1}^T d_i is link i's direction
seen from the reference frame of link i-1), and psi_i the roll of link i's frame about its
axis from F_i: R_i = F_i Rx(psi_i). Joint i is then Rx(-psi_{i-1}) P(c_i) Rx(psi_i), with
P(c) the smallest rotation from x to c. Its two bends depend on psi_{i-1} only (through the
bend-plane angle beta_i = phi_i - psi_{i-1}, phi_i the azimuth of c_i about x) and its twist is
q_i2 = sigma(beta_i) + psi_i - psi_{i-1}, sigma being the roll between the z-y Euler rotation
and the smallest rotation onto the same direction (closed form below). The energy is a sum of
terms in neighbouring rolls: its Hessian in psi is tridiagonal, and Newton's method with
exact derivatives solves it in O(n) a step. Each joint takes the cheaper of the two z-y-x
decompositions of its rotation ((q0, q1, q2) and (q0 + pi, pi - q1, q2 + pi)): bends past 90
degrees out of the base plane need the second. Starts: no twist anywhere, and the first link
rolled by +-90 and 180 degrees (the roll into another bending plane that a search from
untwisted may not find); the lowest energy wins.
"""

import math

import numpy as np
from scipy.linalg import LinAlgError, solveh_banded
from tentacle_planner import paths
from tentacle_planner.errors import PlanInputError

MAX_NEWTON_ITERATIONS = 200
ROLL_STARTS_RAD = (0.0, math.pi / 2, -math.pi / 2, math.pi)
STEP_TOLERANCE_RAD = 1e-13


def target_joint_angles(path, chain, inserted_m):
    """
    Return the joint angles (n, 3), rad, that lay the chain along its target, least strain.

    Per joint bend_1 (about z), bend_2 (about the new y), twist (about the new x), as
    tentacle_model.spatial; the twist is the one a centreline leaves free, chosen by minimum
    strain energy 1/2 q.K.q (module docstring).

    :param path: a paths.Path in the rig frame
    :param chain: tentacle_model.chain.Chain at inserted_m
    :param inserted_m: inserted length, m
    :raises PlanInputError: a path shorter than inserted_m, or a target that needs a joint
        to bend by more than paths.MAX_TURN_DEG
    """
    points = paths.targets(path, chain, inserted_m)
    directions = link_directions(chain, points, path.source)
    try:
        return angles_along(chain, directions)
    except PlanInputError as exc:
        raise PlanInputError(f'{path.source}: {inserted_m * 1e3:g} mm inserted: {exc}') \
            from None


def link_directions(chain, points_m, source='<target>'):
    """
    Return link directions (n, 3): each from where the chain's joint is to the next point.

    :param points_m: (n + 1, 3) target joints and tip, m (paths.targets)
    :raises PlanInputError: a target point on the joint before it
    """
    lengths = np.asarray(chain.lengths_m, dtype=float)
    directions = np.empty((len(lengths), 3))
    joint = np.array(chain.base_position_m, dtype=float)
    for i, length in enumerate(lengths):
        aim = points_m[i + 1] - joint
        distance = float(np.linalg.norm(aim))
        if distance <= 1e-9 * length:
            raise PlanInputError(f'{source}: target point {i + 1} is on joint {i}: no '
                                 f'direction for link {i}')
        directions[i] = aim / distance
        joint = joint + length * directions[i]
    return directions


def angles_along(chain, directions):
    """
    Return joint angles (n, 3), rad, giving the links these directions with least strain.

    :param chain: tentacle_model.chain.Chain (base_rotation and stiffness_n_m are used)
    :param directions: (n, 3) unit link directions, world frame
    :raises PlanInputError: a joint that would bend by more than paths.MAX_TURN_DEG
    """
    problem = _Problem(np.asarray(chain.base_rotation, dtype=float),
                       np.asarray(directions, dtype=float),
                       np.asarray(chain.stiffness_n_m, dtype=float))
    if problem.size == 0:
        return np.zeros((0, 3))
    best = None
    for roll in ROLL_STARTS_RAD:
        psi = problem.minimise(problem.rolls_for_twists(roll))
        energy = problem.terms(psi, derivatives=False)[0]
        if best is None or energy < best[0] - 1e-15 * abs(best[0]):
            best = (energy, psi)
    return problem.joint_angles(best[1])


def _wrap(angle):
    """Return angles wrapped into [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


class _Problem:
    """The roll problem of one chain: per joint the link direction in the reference frame."""

    def __init__(self, base_rotation, directions, stiffness):
        n = len(directions)
        self.size = n
        self.k = stiffness.reshape(n, 3)
        local = np.empty((n, 3))
        frame = base_rotation.copy()
        for i in range(n):
            c = frame.T @ directions[i]
            c /= np.linalg.norm(c)
            local[i] = c
            frame = frame @ paths.rotation_between([1.0, 0.0, 0.0], c)
        self.cos_theta = np.clip(local[:, 0], -1.0, 1.0)
        self.sin_theta = np.hypot(local[:, 1], local[:, 2])
        bend = np.degrees(np.arctan2(self.sin_theta, self.cos_theta))
        if np.any(bend > paths.MAX_TURN_DEG):
            i = int(np.argmax(bend))
            raise PlanInputError(f'joint {i} would bend {bend[i]:.1f} degrees, more than the '
                                 f'{paths.MAX_TURN_DEG:g} the links of the model take')
        self.phi = np.arctan2(local[:, 2], local[:, 1])
        # 1 - cos(theta) without cancellation for small bends.
        self.versine = np.where(self.cos_theta > 0,
                                self.sin_theta ** 2 / (1.0 + np.abs(self.cos_theta)),
                                1.0 - self.cos_theta)

    def _joint(self, previous):
        """Return the bends, sigma and their beta-derivatives (branch a) at previous rolls."""
        ct, st, a = self.cos_theta, self.sin_theta, self.versine
        beta = self.phi - previous
        sb, cb = np.sin(beta), np.cos(beta)
        d2 = np.maximum(ct * ct + st * st * cb * cb, 1e-300)  # cos^2 of bend_2
        d = np.sqrt(d2)
        q0 = np.arctan2(st * cb, ct)
        q1 = -np.arcsin(np.clip(st * sb, -1.0, 1.0))
        q0_1 = -ct * st * sb / d2
        q0_2 = -ct * st * cb * (d2 + 2 * st * st * sb * sb) / (d2 * d2)
        q1_1 = -st * cb / d
        q1_2 = st * sb * (d2 - st * st * cb * cb) / (d2 * d)
        # sigma: x-roll of Ry(-q1) Rz(-q0) P(u), u the direction at bend-plane angle beta.
        s2b, c2b = 2 * sb * cb, cb * cb - sb * sb
        num, den = -0.5 * a * s2b, d2 + ct * a * sb * sb
        num_1, den_1 = -a * c2b, (ct * a - st * st) * s2b
        num_2, den_2 = 2 * a * s2b, 2 * (ct * a - st * st) * c2b
        r2 = np.maximum(num * num + den * den, 1e-300)  # = d2
        cross_1 = den * num_1 - num * den_1
        sigma = np.arctan2(num, den)
        sigma_1 = cross_1 / r2
        sigma_2 = ((den * num_2 - num * den_2) * r2
                   - cross_1 * 2 * (den * den_1 + num * num_1)) / (r2 * r2)
        return q0, q1, sigma, q0_1, q0_2, q1_1, q1_2, sigma_1, sigma_2

    def _branches(self, psi):
        """Return (q0, q1, q2, sign of q1's derivatives, sigma', sigma'', ...) per joint."""
        previous = np.concatenate([[0.0], psi[:-1]])
        q0, q1, sigma, q0_1, q0_2, q1_1, q1_2, sigma_1, sigma_2 = self._joint(previous)
        q2 = _wrap(sigma + psi - previous)
        k0, k1, k2 = self.k[:, 0], self.k[:, 1], self.k[:, 2]
        alt = (_wrap(q0 + math.pi), _wrap(math.pi - q1), _wrap(q2 + math.pi))
        plain = k0 * q0 ** 2 + k1 * q1 ** 2 + k2 * q2 ** 2
        other = k0 * alt[0] ** 2 + k1 * alt[1] ** 2 + k2 * alt[2] ** 2
        use = other < plain
        q0, q1, q2 = (np.where(use, b, a) for a, b in zip((q0, q1, q2), alt))
        sign = np.where(use, -1.0, 1.0)
        return q0, q1, q2, q0_1, q0_2, sign * q1_1, sign * q1_2, sigma_1, sigma_2

    def terms(self, psi, derivatives=True):
        """Return energy, gradient (n,), Hessian diagonal (n,) and superdiagonal (n - 1,)."""
        q0, q1, q2, q0_1, q0_2, q1_1, q1_2, sigma_1, sigma_2 = self._branches(psi)
        k0, k1, k2 = self.k[:, 0], self.k[:, 1], self.k[:, 2]
        energy = 0.5 * float(np.sum(k0 * q0 ** 2 + k1 * q1 ** 2 + k2 * q2 ** 2))
        if not derivatives:
            return energy, None, None, None
        # Joint i's energy in its two rolls: psi_{i-1} (previous) and psi_i (own).
        d_previous = -(k0 * q0 * q0_1 + k1 * q1 * q1_1) - k2 * q2 * (sigma_1 + 1.0)
        dd_previous = (k0 * (q0_1 ** 2 + q0 * q0_2) + k1 * (q1_1 ** 2 + q1 * q1_2)
                       + k2 * ((sigma_1 + 1.0) ** 2 + q2 * sigma_2))
        gradient = k2 * q2
        gradient[:-1] += d_previous[1:]
        diagonal = k2.copy()
        diagonal[:-1] += dd_previous[1:]
        upper = -k2[1:] * (sigma_1[1:] + 1.0)
        return energy, gradient, diagonal, upper

    def rolls_for_twists(self, first_twist):
        """
        Return the rolls psi (n,) that make every twist zero but the first joint's.

        Each joint in the decomposition whose bends cost less (a bend past 90 degrees out of
        the plane has no twist-free form in the first).
        """
        psi = np.empty(self.size)
        previous = 0.0
        for i in range(self.size):
            beta = self.phi[i] - previous
            sb, cb = math.sin(beta), math.cos(beta)
            ct, st, a = self.cos_theta[i], self.sin_theta[i], self.versine[i]
            d2 = ct * ct + st * st * cb * cb
            sigma = math.atan2(-a * sb * cb, d2 + ct * a * sb * sb)
            q0, q1 = math.atan2(st * cb, ct), -math.asin(min(1.0, max(-1.0, st * sb)))
            k0, k1 = self.k[i, 0], self.k[i, 1]
            plain = k0 * q0 ** 2 + k1 * q1 ** 2
            other = k0 * _wrap(q0 + math.pi) ** 2 + k1 * _wrap(math.pi - q1) ** 2
            psi[i] = (previous + (first_twist if i == 0 else 0.0) - sigma
                      - (math.pi if other < plain else 0.0))
            previous = psi[i]
        return psi

    def minimise(self, psi):
        """Return the rolls at a minimum of the energy, by damped Newton from psi."""
        energy, gradient, diagonal, upper = self.terms(psi)
        scale = float(np.max(np.abs(self.k))) or 1.0
        for _ in range(MAX_NEWTON_ITERATIONS):
            step = self._newton_step(gradient, diagonal, upper, scale)
            slope = float(gradient @ step)
            if slope >= 0:
                break
            t = 1.0
            for _ in range(60):
                trial = psi + t * step
                trial_energy = self.terms(trial, derivatives=False)[0]
                if trial_energy <= energy + 1e-4 * t * slope:
                    break
                t *= 0.5
            else:
                break  # no decrease left to find: at the minimum to round-off
            psi = trial
            energy, gradient, diagonal, upper = self.terms(psi)
            if t * np.max(np.abs(step)) < STEP_TOLERANCE_RAD:
                break
        return psi

    @staticmethod
    def _newton_step(gradient, diagonal, upper, scale):
        """Return -(H + lambda I)^-1 g, lambda the least (0 first) that makes H positive."""
        n = len(gradient)
        damping = 0.0
        for _ in range(40):
            bands = np.zeros((2, n))
            bands[0, 1:] = upper
            bands[1] = diagonal + damping
            try:
                return solveh_banded(bands, -gradient)
            except (LinAlgError, ValueError):
                damping = max(10 * damping, 1e-10 * scale)
        return -gradient / scale

    def joint_angles(self, psi):
        """Return the joint angles (n, 3) at these rolls."""
        q0, q1, q2 = self._branches(psi)[:3]
        return np.column_stack([q0, q1, q2])
