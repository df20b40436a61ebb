"""
A tentacle in a scene, built once, for repeated solves: the planner's and simulator's model.

``TentacleModel`` holds what does not change between solves (the tentacle, the joint model,
sub-links, gravity, magnet-to-magnet interaction, the solver's budgets) and caches the
CHAIN_CACHE_SIZE chains last used, by inserted length (a simulator fed continuous stage
positions asks for a new length every frame: the cache stays bounded). It has one state
representation whatever the joint model: joint angles (n, 3), rad, per joint bend_1 (in
the base plane), bend_2 and twist (spatial.py); a planar model's state has only bend_1,
and ``link_angles`` is its absolute-angle view. A state is
carried from one inserted length to the next (``carry``): the chain grows at the base as the
body goes in, so joints are matched by material coordinate.

Solves are deterministic: the iteration budget decides the result, and the wall-clock limit
only guards against a hang, so the same inputs give the same state on any machine. A caller
with a deadline of its own (a simulator at camera rate) gives a solve ``time_limit_s``: the
result then may be unconverged, and says so; solving on from its state continues the descent.

``field_sensitivity`` differentiates the equilibrium implicitly: the gradient g(q*, B) = 0
at every equilibrium, so H dq = -(dg/dB) dB with H the Hessian at q*, and
dg/dB = -(a_e x V_J(e)) for each elementary joint e (the torque balance of
torque_balance.py, whose closed forms this shares). ``moment_sensitivity`` does the same for
the links' magnetic moments (link frame), the planner's magnetisation unknowns.
"""

from collections import OrderedDict
from dataclasses import dataclass, replace

import numpy as np
from tentacle_model import link_loads, planar, spatial, spatial_newton, statics, torque_balance
from tentacle_model.chain import Chain, discretise

DEFAULT_ITERATIONS = 200
HANG_GUARD_S = 60.0  # wall-clock limit: a guard only, never what decides a result
CHAIN_CACHE_SIZE = 64  # chains kept: a plan's key and playback steps, a simulator's recent


@dataclass(frozen=True)
class Solution:
    """An equilibrium at one inserted length, in the model's state representation."""

    inserted_m: float
    state: np.ndarray         # (n, 3) joint angles, rad
    equilibrium: statics.Equilibrium
    chain: Chain              # what was solved (its moments are the ones solved with)

    @property
    def points_m(self):
        """Return the joints and the tip (n + 1, 3), m, world frame."""
        return self.equilibrium.points_m


@dataclass(frozen=True)
class Sensitivity:
    """Derivatives of an equilibrium with respect to p parameters (field, or moments)."""

    state: np.ndarray    # (n, 3, p) d q / d parameter: [joint, angle, parameter], rad per unit
    points: np.ndarray   # (n + 1, 3, p) d points / d parameter: [point, xyz, parameter], m
    hessian: np.ndarray  # (N, N) at the equilibrium in the free joint angles, N m/rad^2


class TentacleModel:
    """One tentacle in one scene: chains cached per inserted length, solves from a state."""

    def __init__(self, spec, *, dof=3, sublinks=1, gravity_m_s2=(0.0, 0.0, 0.0),
                 dipoles=False, backbone_m=0.0, tol=1e-9, max_iterations=DEFAULT_ITERATIONS):
        """
        Fix the model.

        :param spec: a TentacleSpec (tentacle_spec.py)
        :param dof: 1 (planar joints) or 3 (bend, bend, twist)
        :param sublinks: links per segment
        :param gravity_m_s2: (3,) world frame
        :param dipoles: magnet-to-magnet interaction between segments
        :param backbone_m: how far the backbone reaches past the base, m
        :param tol: convergence tolerance (statics.solve)
        :param max_iterations: Newton iterations per solve: what decides a result
        :raises ValueError: dof not 1 or 3, or a bad knob (chain.discretise)
        """
        if dof not in (1, 3):
            raise ValueError(f'dof {dof} is not 1 or 3')
        self.spec, self.dof, self.sublinks = spec, dof, sublinks
        self.gravity_m_s2 = np.asarray(gravity_m_s2, dtype=float)
        self.dipoles, self.backbone_m = dipoles, backbone_m
        self.tol, self.max_iterations = tol, max_iterations
        self._chains = OrderedDict()  # least recently used first
        self._last_evaluation = None  # (solution, field, _evaluate's result)
        self._last_sensitivities = None  # (solution, field, _compiled's result)
        self.chain(spec.length_m)  # a bad knob is refused now, not at the first solve

    def chain(self, inserted_m, backbone_m=None):
        """
        Return the Chain at an inserted length (m), built once.

        :param backbone_m: how far the backbone reaches past the base, m (default the
            model's): a backbone schedule moves it from step to step
        """
        backbone = self.backbone_m if backbone_m is None else float(backbone_m)
        key = (round(float(inserted_m), 12), round(backbone, 12))
        chain = self._chains.get(key)
        if chain is None:
            chain = self._chains[key] = discretise(self.spec, key[0], self.sublinks, key[1])
            if len(self._chains) > CHAIN_CACHE_SIZE:
                self._chains.popitem(last=False)
        else:
            self._chains.move_to_end(key)
        return chain

    def straight(self, inserted_m):
        """Return the straight state (n, 3) at an inserted length."""
        return np.zeros((self.chain(inserted_m).size, 3))

    def solve(self, inserted_m, field_t, state=None, moments_a_m2=None, backbone_m=None,
              time_limit_s=HANG_GUARD_S):
        """
        Return the Solution at an inserted length in a field, from a state (default straight).

        :param inserted_m: length pushed past the base, m
        :param field_t: (3,) uniform field, tesla, world frame
        :param state: (n, 3) joint angles to start from, for this inserted length (see carry)
        :param moments_a_m2: (n, 3) link moments (link frame) in place of the tentacle's own:
            the planner's magnetisation
        :param backbone_m: the backbone's reach past the base, m (default the model's)
        :param time_limit_s: this solve's wall-clock budget, s: past it the Solution is the
            descent so far, its equilibrium ``converged`` False and its reason saying so
        :raises ValueError: a state or moments of another shape, a non-finite field, a
            negative or non-finite time limit
        """
        chain = self.chain(inserted_m, backbone_m)
        if moments_a_m2 is not None:
            moments = np.asarray(moments_a_m2, dtype=float)
            if moments.shape != (chain.size, 3) or not np.all(np.isfinite(moments)):
                raise ValueError(f'moments must be finite, of shape ({chain.size}, 3)')
            chain = replace(chain, moments_a_m2=moments)
        start = self.straight(inserted_m) if state is None else np.asarray(state, dtype=float)
        if start.shape != (chain.size, 3):
            raise ValueError(f'state of shape {start.shape} for {chain.size} links at '
                             f'{inserted_m:g} m inserted: carry() it there first')
        if not (np.isfinite(time_limit_s) and time_limit_s >= 0):
            raise ValueError(f'time limit {time_limit_s!r} s must be finite and >= 0')
        initial = np.cumsum(start[:, 0]) if self.dof == 1 else start
        eq = statics.solve(chain, field_t, self.gravity_m_s2, dof=self.dof, initial=initial,
                           tol=self.tol, max_iterations=self.max_iterations,
                           time_limit_s=time_limit_s, dipoles=self.dipoles)
        return Solution(float(inserted_m), self.state_of(eq), eq, chain)

    def state_of(self, eq):
        """Return an Equilibrium's angles as joint angles (n, 3)."""
        if self.dof == 3:
            return np.array(eq.angles_rad, dtype=float).reshape(-1, 3)
        state = np.zeros((len(eq.angles_rad), 3))
        state[:, 0] = planar.joint_angles(np.asarray(eq.angles_rad, dtype=float))
        return state

    @staticmethod
    def link_angles(state):
        """Return a planar state's absolute link angles (n,), rad, in the base plane."""
        return np.cumsum(np.asarray(state)[:, 0])

    def carry(self, state, from_m, to_m):
        """
        Return a state for another inserted length: joints matched by material coordinate.

        The clamp joint keeps its bend; a joint at the same material point keeps its angles;
        joints where the new chain has none before (new material, or a link cut anew at the
        base) start straight. A warm start, not an equilibrium: solve from it.

        :param state: (n, 3) joint angles at from_m
        """
        old = self.chain(from_m)
        state = np.asarray(state, dtype=float)
        if state.shape != (old.size, 3):
            raise ValueError(f'state of shape {state.shape} is not of {old.size} links at '
                             f'{from_m:g} m inserted')
        index = self.carry_index(from_m, to_m)
        out = np.zeros((len(index), 3))
        out[index >= 0] = state[index[index >= 0]]
        return out

    def carry_index(self, from_m, to_m):
        """Return (n_to,): the joint at from_m whose angles each joint at to_m takes, or -1."""
        old, new = self.chain(from_m), self.chain(to_m)
        index = np.full(new.size, -1)
        if old.size == 0 or new.size == 0:
            return index
        tolerance = 1e-9 * self.spec.length_m
        nearest = np.clip(np.searchsorted(old.s_start_m, new.s_start_m), 0, old.size - 1)
        same = np.abs(old.s_start_m[nearest] - new.s_start_m) <= tolerance
        index[same] = nearest[same]
        index[0] = 0   # the clamp joint keeps its bend
        return index

    def stability(self, solution, field_t):
        """
        Return the smallest eigenvalue of the 3-DoF Hessian at a solution, N m / rad^2.

        Every joint's bend_1, bend_2 and twist, whatever the model: for a planar model this
        sees the modes out of the base plane too, which its own Hessian cannot (an in-plane
        equilibrium can be stable in the plane and buckle out of it). > 0: stable.
        """
        return float(np.linalg.eigvalsh(self._evaluate(solution, field_t)[1].hessian)[0])

    def free_angles(self, n):
        """Return the indices of the model's free angles in the flattened (3n,) state."""
        every = np.arange(3 * n)
        return every if self.dof == 3 else every[0::3]

    def _evaluate(self, solution, field_t):
        """Return (chain, Evaluation, free angles, free Hessian) at a solution, the last kept."""
        # The planner asks for the stability and both sensitivities of one solution in turn:
        # one pass over the chain serves them all.
        field = np.asarray(field_t, dtype=float)
        last = self._last_evaluation
        if last is not None and last[0] is solution and np.array_equal(last[1], field):
            return last[2]
        chain = solution.chain
        state = spatial.evaluate(chain, solution.state, field, self.gravity_m_s2, True, None,
                                 link_loads.of_chain(chain, self.dipoles))
        free = self.free_angles(chain.size)
        result = chain, state, free, state.hessian[np.ix_(free, free)]
        self._last_evaluation = (solution, field.copy(), result)
        return result

    def _points_jacobian(self, state, free):
        """Return d p / d q (n + 1, 3, N) for the free angles: a_e x (p_k - p_j(e)), k > j."""
        n = len(state.points_m) - 1
        joint = free // 3
        axes = state.axes.reshape(-1, 3)[free]                     # (N, 3)
        lever = state.points_m[:, None, :] - state.points_m[joint][None, :, :]  # (n+1, N, 3)
        jac = spatial.cross(np.broadcast_to(axes, lever.shape), lever)
        jac *= (np.arange(n + 1)[:, None] > joint[None, :])[:, :, None]
        return np.transpose(jac, (0, 2, 1))

    def field_sensitivity(self, solution, field_t):
        """
        Return the Sensitivity of an equilibrium to the field it was solved in (p = 3).

        :param field_t: (3,) the field of the solve, tesla
        :raises numpy.linalg.LinAlgError: the Hessian is singular (no isolated equilibrium)
        """
        if self._compiled_sensitivities:
            return self._compiled(solution, field_t)[0]
        chain, state, free, hessian = self._evaluate(solution, field_t)
        dg_db = -spatial.cross(state.axes, state.distal_moments[:, None, :]).reshape(-1, 3)
        return self._implicit(chain, state, free, hessian, dg_db)

    def moment_sensitivity(self, solution, field_t):
        """
        Return the Sensitivity to each link's moment (p = 3n: link, component), per A m^2.

        The moments are the links' own, in the link frame (chain.moments_a_m2); the planner's
        magnetisation directions chain onto them. Without magnet-to-magnet interaction (with
        it the interaction depends on the moments too).

        :raises ValueError: the model has dipoles
        """
        if self.dipoles:
            raise ValueError('moment sensitivity is not available with dipoles=True')
        if self._compiled_sensitivities:
            return self._compiled(solution, field_t)[1]
        chain, state, free, hessian = self._evaluate(solution, field_t)
        n = chain.size
        d_moment = torque_balance.residual_3dof(chain, solution.state, field_t)[2]
        return self._implicit(chain, state, free, hessian, -d_moment.reshape(3 * n, 3 * n))

    @property
    def _compiled_sensitivities(self):
        """Return whether both sensitivities come from one compiled pass (3-DoF, no dipoles)."""
        return self.dof == 3 and not self.dipoles

    def _compiled(self, solution, field_t):
        """Return (field, moment) Sensitivities of a 3-DoF solution, the last pair kept."""
        # The planner asks for both of every solution in turn: one factorisation serves both.
        field = np.asarray(field_t, dtype=float)
        last = self._last_sensitivities
        if last is not None and last[0] is solution and np.array_equal(last[1], field):
            return last[2]
        state = self._evaluate(solution, field)[1]
        dq_field, dq_moment, dp_field, dp_moment = spatial_newton.sensitivities(
            state.rotations, state.axes, state.points_m, state.distal_moments, state.hessian,
            field, np.arange(3 * solution.chain.size))
        n = solution.chain.size
        result = (Sensitivity(dq_field.reshape(n, 3, 3), dp_field, state.hessian),
                  Sensitivity(dq_moment.reshape(n, 3, 3 * n), dp_moment, state.hessian))
        self._last_sensitivities = (solution, field.copy(), result)
        return result

    def _implicit(self, chain, state, free, hessian, dg_dp):
        """Return the Sensitivity from dg/dp (3n, p) by H dq = -(dg/dp) dp."""
        n, p = chain.size, dg_dp.shape[1]
        dq_free = -np.linalg.solve(hessian, dg_dp[free])           # (N, p)
        dq = np.zeros((3 * n, p))
        dq[free] = dq_free
        points = np.einsum('kxe,ep->kxp', self._points_jacobian(state, free), dq_free)
        return Sensitivity(dq.reshape(n, 3, p), points, hessian)
