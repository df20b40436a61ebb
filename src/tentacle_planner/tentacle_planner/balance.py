"""
The thesis' objective as a fast first stage: torque balance at the target shape.

Thesis eq. 3.3 / 5.2: with each key step's target joint angles Q_k prescribed (the chain laid
along its follow-the-leader target, twist by least strain energy: target_angles.py), the
residual lambda = -dE/dq (Q_k; m, B_k) (tentacle_model.torque_balance.residual_3dof) is zero
exactly when the target is an equilibrium. It needs no equilibrium solve, so an evaluation
costs a fraction of the forward model's; but it says nothing of stability or of which
equilibrium the rig reaches as it inserts, so its plans are verified in the forward model
(``plan``) and optimise(first_stage=True) polishes them on the forward-model objective.
"""

from dataclasses import replace
import math

import numpy as np
from tentacle_model.torque_balance import residual_3dof
from tentacle_planner.optimise import MILLITESLA
from tentacle_planner.target_angles import angles_along, link_directions


class BalanceProblem:
    """A Problem's unknowns and limits, with the torque balance at its targets as residual."""

    def __init__(self, problem):
        """Take a Problem (optimise.Problem): its model, steps, targets and constraints."""
        self.problem = problem
        model = problem.model
        self._angles = []
        for inserted_m, backbone_m, target in zip(problem.steps_m, problem.backbones_m,
                                                  problem.targets):
            chain = model.chain(inserted_m, backbone_m)
            angles = angles_along(chain, link_directions(chain, target))
            if model.dof == 1:
                angles[:, 1:] = 0.0
            self._angles.append(angles)
        self.evaluations = 0

    def __getattr__(self, name):
        # The unknowns, bounds, limits and the forward-model plan are the Problem's.
        return getattr(self.problem, name)

    def residuals(self, x, jacobian=True):
        """
        Return (r, J): per step lambda / (k sqrt(steps N_k)) over its free joint angles.

        Each elementary joint's torque imbalance over its stiffness (rad: how far that joint
        alone would have to move), so that sum r^2 is a mean square over steps and joints.
        """
        self.evaluations += 1
        p, model = self.problem, self.problem.model
        directions, fields = p.unpack(x)
        n_dir = len(p.free_segments) * p.angles_per_segment
        rows, jacobians = [], []
        for k, (inserted_m, angles, field_t) in enumerate(zip(p.steps_m, self._angles,
                                                              fields)):
            chain = replace(model.chain(inserted_m, p.backbones_m[k]),
                            moments_a_m2=p._moments(directions, inserted_m))
            lam, d_field, d_moment = residual_3dof(chain, angles, field_t,
                                                   model.gravity_m_s2)
            free = np.arange(3 * chain.size)[0::3 if model.dof == 1 else 1]
            scale = 1.0 / (chain.stiffness_n_m.reshape(-1)[free]
                           * math.sqrt(len(p.steps_m) * len(free)))
            rows.append(lam.reshape(-1)[free] * scale)
            if not jacobian:
                continue
            jac = np.zeros((len(free), p.size))
            d_b = d_field.reshape(-1, 3)[free] * (scale[:, None] * MILLITESLA)
            if p.field_size == 2:
                d_b = d_b @ p.base_plane
            start = n_dir + k * p.field_size
            jac[:, start:start + p.field_size] = d_b
            if n_dir:
                d_m = d_moment.reshape(3 * chain.size, chain.size, 3)[free]
                d_m = d_m * scale[:, None, None]
                jac[:, :n_dir] = p.by_direction_angles(d_m, inserted_m, x)
            jacobians.append(jac)
        return np.concatenate(rows), np.vstack(jacobians) if jacobian else None

    def objective(self, x):
        """Return (sum r^2, its gradient)."""
        r, jac = self.residuals(x)
        return float(r @ r), 2 * jac.T @ r
