"""
The planner's optimisation: a magnetisation direction per segment and a field per step.

Unknowns: the direction of each magnetised segment's magnetisation in its own link frame
(magnitude fixed: one magnetising step; an angle in the link's x-y plane, and an elevation
out of it unless the magnetisation must be planar) and the uniform field of every insertion
step (in the base plane for a planar model). The objective is what the tentacle will do:
the equilibrium of the forward model at every step, warm-started along the insertion as the
rig runs it, against the follow-the-leader target of that step (its joints and tip on the
path), as the mean squared distance over the tentacle length squared. Its gradient is
exact: the equilibrium's sensitivities to field and moments (tentacle_model.model) chained
onto the unknowns; an equilibrium at step k depends on the field of step k only.

With a KeepOff, each link's gap to every obstacle and wall under a margin adds to it.

Constraints (SLSQP): per-axis field limits, a total field limit, a largest field change
between steps, a largest angle between neighbouring magnetisations (approached as weighted
residuals first: polish); a distal segment held axial, or every segment axial (the
tip-driven baseline) removes those unknowns. Global search is a seeded multi-start of
insertion-order starts, fitted two at a time on two cores; the best plan whose every step
is a stable converged equilibrium, and that runs least deep into a wall, wins. A seed
reproduces a plan exactly, on any number of cores: budgets, not clocks, end every stage.
"""

import contextlib
from dataclasses import dataclass, field, replace
from functools import partial
import itertools
import math
import multiprocessing
import signal

import numpy as np
from scipy.optimize import least_squares, minimize
from tentacle_model import spatial, statics
from tentacle_planner import step_residuals, unknowns
from tentacle_planner.clearance import gap_arrays, link_gap_gradients, link_gaps
from tentacle_planner.step_residuals import FAILED_RESIDUAL
from threadpoolctl import threadpool_limits

MILLITESLA = 1e-3  # field unknowns are in mT: of the order of the angles, for the optimiser
MIN_STABILITY_MARGIN = 0.1
"""The stability margin under which the objective adds a penalty: the smallest 3-DoF Hessian
eigenvalue at a step over that of the straight, unloaded body (its stiffness alone)."""
STABILITY_WEIGHT = 0.1  # the penalty at zero margin: as much as a shape error of 10% of L
STAGE_GOOD = 1e-6       # a stage of the insertion-order start this close needs no more tries
MARGIN_STEP = 1e-4      # forward-difference step of the margin's derivative (rad, mT)
KEEP_OFF_WEIGHT = 10.0  # a link this far inside the margin costs 10 times the shape error
NEIGHBOUR_WEIGHTS = (0.03, 0.3, 3.0)  # the neighbour-angle residuals' weights in turn (polish)
ROUND_STARTS = 2        # random starts a round: fitted side by side on two cores


@dataclass(frozen=True)
class Constraints:
    """What a plan must respect; None: no such limit."""

    max_field_t: float | None = None          # each coil axis, every step, T
    max_total_field_t: float | None = None    # |B| at every step, T
    max_field_change_t: float | None = None   # each axis, between consecutive steps, T
    planar_magnetisation: bool = False        # directions in the link's x-y plane
    max_neighbour_angle_rad: float | None = None
    distal_axial: bool = False                # the tip segment magnetised along its axis
    tip_driven: bool = False                  # every segment axial: fields only (baseline)


@dataclass(frozen=True)
class KeepOff:
    """Obstacles and walls a plan keeps its body off, by a margin, m (scene.Sphere, Wall)."""

    spheres: tuple = ()
    walls: tuple = ()
    margin_m: float = 2e-4
    weight: float = KEEP_OFF_WEIGHT


@dataclass(frozen=True)
class Step:
    """One insertion step of a plan, as the forward model predicts it."""

    inserted_m: float
    field_t: np.ndarray            # (3,) world frame
    points_m: np.ndarray           # (n + 1, 3) predicted joints and tip
    shape_rms_m: float
    tip_error_m: float
    stability: float               # smallest 3-DoF Hessian eigenvalue, N m/rad^2 (> 0: stable)
    converged: bool
    backbone_m: float = 0.0        # how far the backbone reached past the base, m
    link_radii_m: np.ndarray | None = None   # (n,) each link's section radius, m


@dataclass(frozen=True)
class Plan:
    """Magnetisation directions (segments, 3; link frame; zero for passive), fields, steps."""

    directions: np.ndarray
    steps: list
    objective: float
    evaluations: int
    flags: list = field(default_factory=list)
    interrupted: bool = False       # Ctrl-C during the search: the best plan so far

    @property
    def fields_t(self):
        """Return the fields (steps, 3), T."""
        return np.array([s.field_t for s in self.steps])

    @property
    def shape_rms_m(self):
        """Return the shape error over every step: RMS of the point distances, m."""
        return float(np.sqrt(np.mean([s.shape_rms_m ** 2 for s in self.steps])))


class Problem:
    """A plan's unknowns, objective with its gradient, and constraints."""

    def __init__(self, model, steps_m, targets_m, constraints=Constraints(),
                 directions=None, start=None, free=None, min_margin=MIN_STABILITY_MARGIN,
                 backbones_m=None, keep_off=None):
        """
        Set up the problem.

        :param model: a TentacleModel (its joint model, sub-links, gravity, dipoles)
        :param steps_m: inserted lengths of the key steps, m, in order (increasing, or
            repeated where a backbone schedule moves the backbone instead)
        :param targets_m: per step, (n_k + 1, 3) the target of the chain's joints and tip, m
        :param constraints: Constraints
        :param directions: (segments, 3) magnetisation directions to hold fixed (fields only)
        :param start: (state, inserted_m) the rig is in before the first step (default: the
            first step starts straight)
        :param free: with directions: the segments whose directions are unknowns after all
        :param min_margin: the stability margin under which a step is penalised (0: never)
        :param backbones_m: per step, how far the backbone reaches past the base, m (default:
            the model's own at every step)
        :param keep_off: a KeepOff: each link's gap to each of its obstacles and walls under
            the margin adds a residual, weight (margin - gap) / (L sqrt(steps)); None: none
        """
        self.model, self.constraints = model, constraints
        self.steps_m = [float(s) for s in steps_m]
        self.backbones_m = [model.backbone_m] * len(self.steps_m) if backbones_m is None \
            else [float(b) for b in backbones_m]
        self.targets = [np.asarray(t, dtype=float) for t in targets_m]
        self.length_m = model.spec.length_m
        for s, t in zip(self.steps_m, self.targets):
            if t.shape != (model.chain(s).size + 1, 3):
                raise ValueError(f'target at {s:g} m has shape {t.shape}, not '
                                 f'({model.chain(s).size + 1}, 3)')
        strength = [float(np.linalg.norm(seg.magnetisation_a_per_m))
                    for seg in model.spec.segments]
        self.magnetised = [i for i, m in enumerate(strength) if m > 0]
        last = len(model.spec.segments) - 1
        fixed = set(self.magnetised) if constraints.tip_driven else (
            {last} & set(self.magnetised) if constraints.distal_axial else set())
        if directions is not None:
            fixed |= set(self.magnetised) - set(free or ())
        self.free_segments = [i for i in self.magnetised if i not in fixed]
        self.fixed_directions = None if directions is None else np.asarray(directions, float)
        self.start, self.min_margin = start, min_margin
        self.angles_per_segment = 1 if constraints.planar_magnetisation else 2
        self.field_size = 2 if model.dof == 1 else 3
        self.base_plane = model.spec.base_rotation[:, :2]
        # unpack's and the neighbour rows' fixed arguments (unknowns.py)
        self._held = np.zeros((len(model.spec.segments), 3))
        for i in self.magnetised:
            self._held[i] = (1.0, 0.0, 0.0) if self.fixed_directions is None else \
                self.fixed_directions[i]
        self._free = np.array(self.free_segments, dtype=np.intp)
        column = {i: k * self.angles_per_segment for k, i in enumerate(self.free_segments)}
        pairs = np.array(self._neighbour_pairs(), dtype=np.intp).reshape(-1, 2)
        self._pairs = (pairs[:, 0].copy(), pairs[:, 1].copy(),
                       *(np.array([column.get(i, -1) for i in side], dtype=np.intp)
                         for side in pairs.T))
        # Each link's moment magnitude is fixed; its direction is its segment's.
        self._magnitudes = {s: np.linalg.norm(model.chain(s).moments_a_m2, axis=1)
                            for s in self.steps_m}
        self.keep_off = keep_off if keep_off and (keep_off.spheres or keep_off.walls) else None
        self._radii = {s: np.array([model.spec.segments[i].radius_m
                                    for i in model.chain(s).segment_index])
                       for s in self.steps_m}
        self.neighbour_weight = NEIGHBOUR_WEIGHTS[-1]
        # the compiled key step (step_residuals) where the model allows: no dipoles
        self._steps = None if model.dipoles else self._step_arrays()
        # (lower (3,), upper (3,)) each axis of every step's field, T, within the limits: what
        # the rig can reach from the step before (dense playback); 3-axis fields only
        self.field_box_t = None
        self.evaluations = 0
        self._simulated = None   # (x, its Solutions): the last simulated

    def _step_arrays(self):
        """Return each key step's fixed arguments of step_residuals, and what the call needs."""
        model, off = self.model, self.keep_off
        obstacles = gap_arrays(*((off.spheres, off.walls) if off else ((), ())))
        keep = (off.margin_m, off.weight / (self.length_m * math.sqrt(len(self.steps_m)))) \
            if off else (0.0, 0.0)
        newton = np.array([statics.MAX_STEP_RAD, statics.MAX_SADDLE_ESCAPES,
                           statics.ESCAPE_STEP_RAD])
        previous = None if self.start is None else self.start[1]
        out = []
        for inserted_m, backbone_m, target in zip(self.steps_m, self.backbones_m, self.targets):
            chain = model.chain(inserted_m, backbone_m)
            carry = np.full(chain.size, -1) if previous is None else model.carry_index(
                previous, inserted_m)
            weight = 1.0 / (self.length_m * math.sqrt(len(self.steps_m) * len(target)))
            # statics' torque floor: of the joints' stiffness the model has
            modelled = chain.stiffness_n_m if model.dof == 3 else chain.stiffness_n_m[:, 0]
            out.append((carry, (
                chain.base_rotation, chain.base_position_m, chain.lengths_m,
                self._magnitudes[inserted_m], chain.segment_index), (
                spatial.gravity_levers(chain), chain.stiffness_n_m), (
                model.gravity_m_s2, model.tol, max(1e-9 * np.max(modelled), 1e-300),
                model.max_iterations, newton, model.free_angles(chain.size), target, weight,
                self._radii[inserted_m], *obstacles, *keep),
                float(np.min(chain.stiffness_n_m))))
            previous = inserted_m
        first = np.full(len(model.spec.segments), -1)
        first[self.free_segments] = np.arange(len(self.free_segments)) * \
            self.angles_per_segment
        field_map = (self.base_plane if self.field_size == 2 else np.eye(3)) * MILLITESLA
        columns = len(obstacles[1]) + len(obstacles[3])
        offsets = np.cumsum([0] + [(len(carry) + 1) * 3 + 1 + len(carry) * columns
                                   for carry, *_ in out])
        self._columns = first, field_map, offsets
        return out

    # -- unknowns ---------------------------------------------------------------------------
    @property
    def size(self):
        """Return the number of unknowns."""
        return (len(self.free_segments) * self.angles_per_segment
                + len(self.steps_m) * self.field_size)

    def unpack(self, x):
        """Return (directions (segments, 3) link frame, fields (steps, 3) world T)."""
        x = np.asarray(x, dtype=float)
        return (unknowns.directions(x, self._held, self._free, self.angles_per_segment)[0],
                self._fields(x))

    def _fields(self, x):
        """Return the fields (steps, 3) world T of unknowns x (an array)."""
        k = len(self.free_segments) * self.angles_per_segment
        fields = x[k:].reshape(len(self.steps_m), self.field_size) * MILLITESLA
        return fields @ self.base_plane.T if self.field_size == 2 else fields

    def pack(self, directions, fields_t):
        """Return x for directions (segments, 3) and fields (steps, 3) (inverse of unpack)."""
        values = []
        for i in self.free_segments:
            d = np.asarray(directions[i], dtype=float)
            d = d / np.linalg.norm(d)
            values.append(math.atan2(d[1], d[0]))
            if self.angles_per_segment == 2:
                values.append(math.asin(np.clip(d[2], -1.0, 1.0)))
        fields = np.asarray(fields_t, dtype=float)
        if self.field_size == 2:
            fields = fields @ self.base_plane
        return np.concatenate([values, fields.reshape(-1) / MILLITESLA])

    def _moments(self, directions, inserted_m):
        chain = self.model.chain(inserted_m)
        return self._magnitudes[inserted_m][:, None] * directions[chain.segment_index]

    # -- forward model and objective --------------------------------------------------------
    def simulate(self, x):
        """
        Return the Solutions of every step, warm-started along the insertion.

        The last x's are kept: plan() simulates x and then asks residuals() for the objective
        at the same x, which (for models with the magnets' interaction) simulates it again.
        """
        x = np.asarray(x, dtype=float)
        if self._simulated is not None and np.array_equal(self._simulated[0], x):
            return list(self._simulated[1])
        directions, fields = self.unpack(x)
        solutions = []
        state, previous = (None, None) if self.start is None else self.start
        for inserted_m, backbone_m, field_t in zip(self.steps_m, self.backbones_m, fields):
            if state is not None:
                state = self.model.carry(state, previous, inserted_m)
            solution = self.model.solve(inserted_m, field_t, state,
                                        self._moments(directions, inserted_m), backbone_m)
            solutions.append(solution)
            state, previous = solution.state, inserted_m
        self._simulated = (x.copy(), solutions)
        return list(solutions)

    def residuals(self, x, jacobian=True):
        """
        Return (r, J): r the scaled residuals of every step, J = dr/dx (or None).

        r stacks, per step, (p - t) / (L sqrt(steps n_k)) over its points and its stability
        penalty (_stability_penalty), so that sum r^2 is the objective; J comes from the
        equilibrium's sensitivities.

        :raises ValueError: a Jacobian for magnetisation unknowns with dipoles (the moment
            sensitivity leaves the interaction out): plan without them, verify with them
        """
        self.evaluations += 1
        if self._steps is not None:
            return self._compiled_residuals(x, jacobian)
        directions, fields = self.unpack(x)
        n_dir = len(self.free_segments) * self.angles_per_segment
        if jacobian and n_dir and self.model.dipoles:
            raise ValueError('planning magnetisation with dipoles is not supported: plan '
                             'without them, then verify with them')
        solutions = self.simulate(x)
        rows, jacobians = [], []
        for k, (solution, target, field_t) in enumerate(zip(solutions, self.targets, fields)):
            weight = 1.0 / (self.length_m * math.sqrt(len(self.steps_m) * len(target)))
            keep_off = self._keep_off_rows(k, solution)
            jac = np.zeros((target.size + 1 + len(keep_off[0]), self.size))
            if not solution.equilibrium.converged or not np.all(np.isfinite(solution.points_m)):
                rows.append(np.concatenate([np.full(target.size + 1, FAILED_RESIDUAL),
                                            np.zeros(len(keep_off[0]))]))
                jacobians.append(jac)   # outside what the rig can rely on
                continue
            penalty, d_penalty = self._stability_penalty(
                k, solution.state, self.margin(solution, field_t), x, jacobian)
            rows.append(np.concatenate([weight * (solution.points_m - target).reshape(-1),
                                        [penalty], keep_off[0]]))
            if not jacobian:
                continue
            # The shape's rows scaled as they always were: a plan depends on the last bit of
            # its Jacobian (bile_duct: 1.2% or 3.5% of L from a 7e-18 difference).
            d_field = self.model.field_sensitivity(solution, field_t).points.reshape(-1, 3)
            columns = slice(n_dir + k * self.field_size, n_dir + (k + 1) * self.field_size)
            jac[:target.size, columns] = self._field_columns(d_field, weight * MILLITESLA)
            if n_dir:
                d_direction = self._direction_jacobian(solution, field_t, x)
                jac[:target.size, :n_dir] = weight * d_direction
            jac[target.size] = d_penalty
            if len(keep_off[0]):   # by the points, d points / dx
                points_by = np.zeros((target.size, self.size))
                points_by[:, columns] = self._field_columns(d_field, MILLITESLA)
                if n_dir:
                    points_by[:, :n_dir] = d_direction
                jac[target.size + 1:] = keep_off[1] @ points_by
            jacobians.append(jac)
        neighbours, d_neighbours = self._neighbour_rows(x, directions)
        rows.append(neighbours)
        jacobians.append(d_neighbours)
        return np.concatenate(rows), np.vstack(jacobians) if jacobian else None

    def _compiled_residuals(self, x, jacobian):
        """Return residuals' (r, J) by the compiled key step (step_residuals.py)."""
        x = np.asarray(x, dtype=float)
        directions, derivatives = unknowns.directions(x, self._held, self._free,
                                                      self.angles_per_segment)
        fields = self._fields(x)
        n_dir = len(self.free_segments) * self.angles_per_segment
        first, field_map, offsets = self._columns
        neighbours, d_neighbours = self._neighbour_rows(x, directions, derivatives)
        r = np.zeros(offsets[-1] + len(neighbours))
        jac = np.zeros((len(r), self.size) if jacobian else (0, 0))
        state = None if self.start is None else np.asarray(self.start[0], dtype=float)
        for k, (carry, chain, stiff, rest, least_stiffness) in enumerate(self._steps):
            rows = slice(offsets[k], offsets[k + 1])
            state, usable, stability = self._kernel(
                step_residuals.carried(state, carry) if state is not None else
                np.zeros((len(carry), 3)), *chain, directions, *stiff, fields[k], *rest,
                derivatives, first, n_dir, field_map, self._field_slice(k).start, r[rows],
                jac[rows] if jacobian else jac, jacobian)
            if usable:   # the stability penalty's row: after the shape's
                row = offsets[k] + 3 * (len(carry) + 1)
                r[row], d_penalty = self._stability_penalty(
                    k, state, stability / least_stiffness, x, jacobian)
                if jacobian:
                    jac[row] = d_penalty
        r[offsets[-1]:] = neighbours
        if jacobian:
            jac[offsets[-1]:] = d_neighbours
        return r, jac if jacobian else None

    @property
    def _kernel(self):
        """Return the compiled key step of the model's joints."""
        return step_residuals.step_residuals if self.model.dof == 3 else \
            step_residuals.planar_step_residuals

    def _field_slice(self, k):
        """Return the columns of step k's field unknowns."""
        start = len(self.free_segments) * self.angles_per_segment + k * self.field_size
        return slice(start, start + self.field_size)

    def _neighbour_pairs(self):
        """Return the neighbouring magnetised segments (a, b) with a direction unknown."""
        free = set(self.free_segments)  # pairs of held directions are no constraint
        return [(a, b) for a, b in zip(self.magnetised, self.magnetised[1:])
                if a + 1 == b and {a, b} & free]

    def _neighbour_rows(self, x, directions, derivatives=None):
        """
        Return (r, dr/dx): the neighbour-angle limit as residuals, ahead of its SLSQP polish.

        One per pair: neighbour_weight (cos limit - d_a . d_b) where the pair is further
        apart than the limit, else 0, so that least squares stays near the limit and SLSQP
        (fit) has only a small step left to keep it exactly.

        :param derivatives: unknowns.directions' second answer at x, if the caller has it
        """
        limit = self.constraints.max_neighbour_angle_rad
        if limit is None:
            return np.zeros(0), np.zeros((0, self.size))
        if derivatives is None:
            derivatives = unknowns.directions(np.asarray(x, dtype=float), self._held,
                                              self._free, self.angles_per_segment)[1]
        return unknowns.neighbour_rows(directions, derivatives, *self._pairs,
                                       math.cos(limit), self.neighbour_weight, self.size)

    def _field_columns(self, d_field, scale):
        """Return d points / d this step's field unknowns from d points / d field (T)."""
        d_field = d_field * scale
        return d_field @ self.base_plane if self.field_size == 2 else d_field

    def _keep_off_rows(self, k, solution):
        """
        Return (r, dr/d points ((n + 1) 3 columns)) of step k's keep-off residuals.

        One per link and obstacle or wall: weight (margin - gap) / (L sqrt(steps)) where the
        gap is under the margin, else 0 (a smooth square in the objective).
        """
        n_points = len(self._radii[solution.inserted_m]) + 1
        if self.keep_off is None:
            return np.zeros(0), np.zeros((0, 3 * n_points))
        off = self.keep_off
        if not np.all(np.isfinite(solution.points_m)):
            count = (n_points - 1) * (len(off.spheres) + len(off.walls))
            return np.zeros(count), np.zeros((count, 3 * n_points))
        gaps, gradients = link_gap_gradients(solution.points_m, self._radii[solution.inserted_m],
                                             off.spheres, off.walls)
        scale = off.weight / (self.length_m * math.sqrt(len(self.steps_m)))
        inside = gaps < off.margin_m
        r = np.where(inside, scale * (off.margin_m - gaps), 0.0).reshape(-1)
        d_r = np.zeros((gaps.shape[0], gaps.shape[1], n_points, 3))
        links = np.arange(gaps.shape[0])
        d_r[links, :, links] = -scale * gradients[:, :, 0] * inside[..., None]
        d_r[links, :, links + 1] = -scale * gradients[:, :, 1] * inside[..., None]
        return r, d_r.reshape(len(r), 3 * n_points)

    def margin(self, solution, field_t):
        """Return a step's stability margin: its 3-DoF stability over the unloaded body's."""
        stability = solution.equilibrium.stability if self.model.dof == 3 else \
            self.model.stability(solution, field_t)
        # Straight and unloaded, the Hessian is the joint stiffness, diagonal.
        return stability / float(np.min(solution.chain.stiffness_n_m))

    def _stability_penalty(self, k, state, margin, x, jacobian):
        """
        Return (penalty, d penalty / dx) of step k: STABILITY_WEIGHT (1 - margin / min_margin).

        Zero at margins of min_margin and more. The derivative is a forward difference of the
        margin, each unknown of the step (its field, the directions) moved in turn and the
        step re-solved from its equilibrium (state): only where the penalty applies.
        """
        d_penalty = np.zeros(self.size)
        if not self.min_margin or margin >= self.min_margin:
            return 0.0, d_penalty
        penalty = STABILITY_WEIGHT * (1.0 - margin / self.min_margin)
        if not jacobian:
            return penalty, d_penalty
        n_dir = len(self.free_segments) * self.angles_per_segment
        for j in [*range(n_dir), *range(self.size)[self._field_slice(k)]]:
            moved = x.copy()
            moved[j] += MARGIN_STEP
            other = self._margin_from(k, state, moved)
            if other is not None:
                d_margin = (other - margin) / MARGIN_STEP
                d_penalty[j] = -STABILITY_WEIGHT / self.min_margin * d_margin
        return penalty, d_penalty

    def _margin_from(self, k, state, x):
        """Return step k's stability margin at x solved from state, or None: not converged."""
        directions, fields = self.unpack(x)
        inserted_m = self.steps_m[k]
        if self._steps is None:
            other = self.model.solve(inserted_m, fields[k], state,
                                     self._moments(directions, inserted_m),
                                     self.backbones_m[k])
            return self.margin(other, fields[k]) if other.equilibrium.converged else None
        carry, chain, stiff, rest, least_stiffness = self._steps[k]
        first, field_map, offsets = self._columns
        _, usable, stability = self._kernel(
            state, *chain, directions, *stiff, fields[k], *rest,
            np.zeros((len(directions), self.angles_per_segment, 3)), first, 0, field_map, 0,
            np.zeros(offsets[k + 1] - offsets[k]), np.zeros((0, 0)), False)
        return stability / least_stiffness if usable else None

    def objective(self, x):
        """Return (objective, gradient (size,)) at x; the objective is dimensionless."""
        r, jac = self.residuals(x)
        return float(r @ r), 2 * jac.T @ r

    def _direction_jacobian(self, solution, field_t, x):
        """Return d points / d direction angles ((n + 1) 3, angles) from moment sensitivity."""
        d_points = self.model.moment_sensitivity(solution, field_t).points  # (n+1, 3, 3n)
        return self.by_direction_angles(d_points.reshape(-1, solution.chain.size, 3),
                                        solution.inserted_m, x)

    def by_direction_angles(self, d_by_moments, inserted_m, x):
        """
        Return d r / d direction angles (rows, angles) from d r / d link moments.

        :param d_by_moments: (rows, n, 3): d r by each link's moment vector (link frame),
            per A m^2; a segment's links share its direction, each with its own magnitude
        """
        chain = self.model.chain(inserted_m)
        magnitudes = self._magnitudes[inserted_m]
        out = np.zeros((d_by_moments.shape[0],
                        len(self.free_segments) * self.angles_per_segment))
        k = 0
        for i in self.free_segments:
            links = chain.segment_index == i
            azimuth = x[k]
            elevation = 0.0 if self.angles_per_segment == 1 else x[k + 1]
            pulled = np.einsum('rlc,l->rc', d_by_moments[:, links], magnitudes[links])
            d_azimuth, d_elevation = _direction_derivatives(azimuth, elevation)
            out[:, k] = pulled @ d_azimuth
            if self.angles_per_segment == 2:
                out[:, k + 1] = pulled @ d_elevation
            k += self.angles_per_segment
        return out

    # -- constraints ------------------------------------------------------------------------
    @property
    def _axes_are_unknowns(self):
        """Return whether each field unknown is one coil axis (so its limit is a bound)."""
        if self.field_size == 3:
            return True
        # A base plane spanned by two coil axes (the usual rig): still one axis each.
        return bool(np.all(np.sum(np.abs(self.base_plane) > 1e-12, axis=0) == 1))

    def bounds(self):
        """Return bounds: the per-axis field limit where the unknowns are the axes."""
        n_dir = len(self.free_segments) * self.angles_per_segment
        limit = self.constraints.max_field_t
        field_bound = (None, None) if limit is None or not self._axes_are_unknowns else (
            -limit / MILLITESLA, limit / MILLITESLA)
        fields = [field_bound] * (len(self.steps_m) * self.field_size)
        if self.field_box_t is not None and self.field_size == 3:
            low, high = (np.asarray(v, float) / MILLITESLA for v in self.field_box_t)
            if field_bound[0] is not None:
                low, high = np.maximum(low, field_bound[0]), np.minimum(high, field_bound[1])
            fields = [(float(a), float(b)) for a, b in zip(low, high)] * len(self.steps_m)
        return [(None, None)] * n_dir + fields

    def inequalities(self):
        """Return SLSQP inequality constraints (fun(x) >= 0) with their Jacobians."""
        c, out = self.constraints, []
        n_dir = len(self.free_segments) * self.angles_per_segment
        steps = len(self.steps_m)
        # world field = F x[n_dir:] (linear): F maps the field unknowns to (steps * 3) axes
        to_world = np.kron(np.eye(steps), (self.base_plane if self.field_size == 2
                                           else np.eye(3)) * MILLITESLA)
        to_world = np.hstack([np.zeros((3 * steps, n_dir)), to_world])
        if c.max_field_t is not None and not self._axes_are_unknowns:
            out += [_linear(to_world, c.max_field_t), _linear(-to_world, c.max_field_t)]
        if c.max_field_change_t is not None and steps > 1:
            change = (np.kron(np.eye(steps)[1:] - np.eye(steps)[:-1], np.eye(3))) @ to_world
            out += [_linear(change, c.max_field_change_t),
                    _linear(-change, c.max_field_change_t)]
        if c.max_total_field_t is not None:
            def total(x):
                b = (to_world @ x).reshape(steps, 3)
                return (c.max_total_field_t ** 2 - np.sum(b ** 2, axis=1)) / MILLITESLA ** 2

            def total_jac(x):
                b = (to_world @ x).reshape(steps, 3)
                rows = -2 * b[:, :, None] * to_world.reshape(steps, 3, -1)
                return rows.sum(axis=1) / MILLITESLA ** 2
            out.append({'type': 'ineq', 'fun': total, 'jac': total_jac})
        pairs = self._neighbour_pairs()
        if c.max_neighbour_angle_rad is not None and pairs:
            cos_limit = math.cos(c.max_neighbour_angle_rad)

            def neighbours(x):
                d = self.unpack(x)[0]
                return np.array([d[a] @ d[b] - cos_limit for a, b in pairs])

            def neighbours_jac(x):
                eps = 1e-7  # the directions' dot products: smooth and cheap to difference
                base = neighbours(x)
                jac = np.zeros((len(pairs), len(x)))
                for j in range(n_dir):
                    moved = x.copy()
                    moved[j] += eps
                    jac[:, j] = (neighbours(moved) - base) / eps
                return jac
            out.append({'type': 'ineq', 'fun': neighbours, 'jac': neighbours_jac})
        return out

    # -- results ----------------------------------------------------------------------------
    def plan(self, x, flags=()):
        """Return the Plan at x, verified in the forward model, with its flags."""
        directions, fields = self.unpack(x)
        steps, flags = [], list(flags)
        for k, (solution, target, field_t) in enumerate(zip(self.simulate(x), self.targets,
                                                            fields)):
            eq = solution.equilibrium
            distances = np.linalg.norm(solution.points_m - target, axis=1)
            # A planar model's own Hessian cannot see the modes out of its plane.
            stability = float(eq.stability) if self.model.dof == 3 or not eq.converged \
                else self.model.stability(solution, field_t)
            steps.append(Step(solution.inserted_m, field_t, solution.points_m,
                              float(np.sqrt(np.mean(distances ** 2))), float(distances[-1]),
                              stability, eq.converged, self.backbones_m[k],
                              self._radii[solution.inserted_m]))
            if not eq.converged:
                flags.append(f'step {k + 1} did not converge: {eq.reason}')
            elif not stability > 0:
                plane = ', out of the base plane' if self.model.dof == 1 and \
                    eq.stability > 0 else ''
                flags.append(f'unstable step {k + 1} (stability {stability:.3g}{plane})')
        flags += self.violations(directions, fields)
        r = self.residuals(x, jacobian=False)[0]
        return Plan(directions, steps, float(r @ r), self.evaluations, flags)

    def deepest_contact_m(self, plan):
        """Return how far a plan's body runs into its KeepOff's obstacles and walls, m (0: not)."""
        if self.keep_off is None:
            return 0.0
        gaps = [np.min(link_gaps(s.points_m, self._radii[s.inserted_m], self.keep_off.spheres,
                                 self.keep_off.walls)) for s in plan.steps]
        return max(0.0, -float(np.nanmin(gaps)))

    def rank(self, plan, error, flags=0):
        """
        Return (flags, how deep into a wall, error) of a plan: the lower, the better.

        :param error: what decides between plans that are alike there (the objective, or
            the re-checked shape error)
        :param flags: flags the plan's own list does not carry (a re-check's)
        """
        return len(plan.flags) + flags, self.deepest_contact_m(plan), error

    def violations(self, directions, fields, tolerance=1e-6):
        """Return what breaks a constraint, one line each (relative tolerance)."""
        c, out = self.constraints, []
        for k, b in enumerate(fields):
            if c.max_field_t is not None and np.max(np.abs(b)) > c.max_field_t * (1 + tolerance):
                out.append(f'field over the per-axis limit at step {k + 1}: '
                           f'{np.max(np.abs(b)) * 1e3:.3f} mT')
            if c.max_total_field_t is not None and np.linalg.norm(b) > c.max_total_field_t * (
                    1 + tolerance):
                out.append(f'field over the total limit at step {k + 1}: '
                           f'{np.linalg.norm(b) * 1e3:.3f} mT')
            if k and c.max_field_change_t is not None and np.max(
                    np.abs(b - fields[k - 1])) > c.max_field_change_t * (1 + tolerance):
                out.append(f'field change over the limit into step {k + 1}')
        if c.max_neighbour_angle_rad is not None:
            for a, b in zip(self.magnetised, self.magnetised[1:]):
                angle = math.acos(np.clip(directions[a] @ directions[b], -1.0, 1.0))
                if a + 1 == b and angle > c.max_neighbour_angle_rad + 1e-4:
                    out.append(f'segments {a + 1} and {b + 1} magnetised '
                               f'{math.degrees(angle):.1f} deg apart')
        return out


def _direction(azimuth, elevation):
    return np.array([math.cos(elevation) * math.cos(azimuth),
                     math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])


def _direction_derivatives(azimuth, elevation):
    ca, sa, ce, se = (math.cos(azimuth), math.sin(azimuth), math.cos(elevation),
                      math.sin(elevation))
    return np.array([-ce * sa, ce * ca, 0.0]), np.array([-se * ca, -se * sa, ce])


def _linear(matrix, limit):
    """Return the constraint limit / mT - matrix x / mT >= 0 (one row each)."""
    return {'type': 'ineq', 'fun': lambda x: (limit - matrix @ x) / MILLITESLA,
            'jac': lambda x: -matrix / MILLITESLA}


def optimise(problem, **options):
    """Return the best Plan over a seeded multi-start: leading(problem, keep=1, ...)[0]."""
    return leading(problem, keep=1, **options)[0]


def leading(problem, *, keep=2, seed=0, starts=8, iterations=100, initial=None, progress=None,
            first_stage=False, min_gain=None, workers=1):
    """
    Return the keep best Plans, best first, of a seeded multi-start fitted by Gauss-Newton.

    Fewer where fewer starts were fitted (one after Ctrl-C: the best so far). A start is the
    insertion-order start (the rig's own order, its stages' tries drawn from the start's own
    seed), or for other objectives (the torque balance) a random one. They come in rounds of
    ROUND_STARTS, fitted side by side by ``workers`` processes; the rounds, and so the plan,
    are the same for any number of workers.

    :param keep: plans to return, at most
    :param starts: starts, at most (1 where only fields are unknown: the steps separate)
    :param iterations: model evaluations per start (and SLSQP iterations where limits other
        than per-axis bounds apply): the budget that ends each start
    :param initial: an x to try first (e.g. the tip-driven baseline or a previous plan)
    :param progress: called with (starts done, starts at most, best objective so far) after
        each, and with (steps fitted, steps, None) while this process builds an
        insertion-order start
    :param first_stage: fit each start on the thesis' torque balance first (balance.py),
        then on the forward model
    :param min_gain: end the search once a round lowers the best objective by less than
        this fraction of it (not after the first round, nor while the best plan is flagged
        or touches a wall; None or 0: every start)
    :param workers: processes fitting a round's starts side by side (forked from this one)
    """
    from tentacle_planner.balance import BalanceProblem  # it builds on this module
    n_dir = len(problem.free_segments) * problem.angles_per_segment
    ordered = isinstance(problem, Problem)
    if ordered and not n_dir:
        # Fields alone: each step's equilibrium depends on its own field and the state
        # before it, so the steps separate and the insertion-order start, which fits them
        # in turn as the rig runs them, is the search: its stages draw nothing.
        starts = min(starts, 1)
    seeds = np.random.SeedSequence(seed)
    fitter = _Fitter(problem, BalanceProblem(problem) if first_stage else None, iterations)
    kind = 'ordered' if ordered else 'random'
    # Each start's seed is spawned when its turn comes: a million take no memory.
    jobs = itertools.chain([] if initial is None else [('fit', np.asarray(initial, float))],
                           ((kind, seeds.spawn(1)[0]) for _ in range(starts)))
    search = _Search(problem, (initial is not None) + starts, progress)
    try:
        with fitter.workers(workers if (initial is not None) + starts > 1 else 1):
            while True:
                batch = list(itertools.islice(jobs, ROUND_STARTS))
                if not batch:
                    break
                before = search.best_objective
                pending = [fitter.submit(job) for job in batch[:-1]]
                search.consider(fitter.run(batch[-1], progress))   # the last one: here
                for result in pending:
                    search.consider(result())
                best = search.best_objective
                # Not on an objective alone, however small: a plan the planning model
                # fits exactly may be one the finer model does not reproduce (refine).
                if min_gain and before is not None and search.clean and \
                        before - best < min_gain * before:
                    break
    except StartInterrupted as exc:
        # Ctrl-C while this process built an insertion-order start (all of a fields-only
        # search): the best plan so far, or the steps fitted, the rest holding the last field.
        if search.best is not None:
            return [search.interrupted(fitter)]
        plan = problem.plan(np.clip(exc.x, *_limits(problem)))
        return [replace(plan, interrupted=True,
                        flags=plan.flags + [f'interrupted: the best plan so far (the first '
                                            f'{exc.fitted} of {len(problem.steps_m)} '
                                            'steps fitted)'])]
    except KeyboardInterrupt:
        # Ctrl-C keeps the best plan so far (or the start itself, if none is done).
        if search.best is None and fitter.last_start is None:
            raise
        return [search.interrupted(fitter)]
    return [plan for _, _, plan in search.ranked[:keep]]


def clean(rank):
    """Return whether a plan of this Problem.rank has no flag and touches nothing."""
    return rank[:2] == (0, 0.0)


class _Search:
    """
    The best plan so far.

    One that relies on no unstable step and breaks no limit beats any that does, then one
    that runs less deep into a wall, then the one of lower objective.
    """

    def __init__(self, problem, total, progress):
        self.problem, self.total, self.progress = problem, total, progress
        self.ranked, self.done = [], 0   # [(key, order, plan)], best first

    @property
    def best(self):
        """Return the best plan so far (None before any)."""
        return self.ranked[0][2] if self.ranked else None

    @property
    def clean(self):
        """Return whether the best plan so far has no flag and touches nothing."""
        return bool(self.ranked) and clean(self.ranked[0][0])

    @property
    def best_objective(self):
        """Return the best plan's objective (None before any)."""
        return None if self.best is None else self.best.objective

    def consider(self, x):
        """Take a fitted x as a candidate."""
        plan = self.problem.plan(x)
        self.ranked.append((self.problem.rank(plan, plan.objective), self.done, plan))
        self.ranked.sort(key=lambda entry: entry[:2])   # of equals, the earlier start
        self.done += 1
        if self.progress is not None:
            self.progress(self.done, self.total, self.best.objective)

    def interrupted(self, fitter):
        """Return the best plan so far (or the last start, clipped), marked interrupted."""
        fallback = self.best or self.problem.plan(np.clip(fitter.last_start,
                                                          *_limits(self.problem)))
        return replace(fallback, interrupted=True,
                       flags=fallback.flags + ['interrupted: the best plan so far'])


_WORKER_FITTER = None   # the _Fitter whose starts forked workers fit (set before the fork)


def _fit_in_worker(job):
    """Return (x, model evaluations spent): a start job run in a worker."""
    before = _WORKER_FITTER.problem.evaluations
    return _WORKER_FITTER.run(job), _WORKER_FITTER.problem.evaluations - before


_WORKER_BLAS = []   # a worker's one-thread BLAS limit, held for its life


def _quiet_worker():
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # Ctrl-C is the parent's to handle
    _WORKER_BLAS.append(threadpool_limits(limits=1, user_api='blas'))


@contextlib.contextmanager
def _forked(processes):
    """
    Yield a pool of processes forked from this one (None for none), all on one BLAS thread.

    One BLAS thread here and in every worker, whatever the count: the matrices are small,
    and two processes' BLAS threads contending for two cores made a round of two starts 1.5
    times as long (pancreatic_duct); the same threads for any count keep the plans the same.
    """
    with threadpool_limits(limits=1, user_api='blas'):
        pool = multiprocessing.get_context('fork').Pool(processes, _quiet_worker) \
            if processes > 0 else None
        try:
            yield pool
        finally:
            if pool is not None:
                pool.terminate()
                pool.join()


_SIDE_BY_SIDE = None   # the function side_by_side's forked workers call (set before the fork)


def _call_in_worker(item):
    return _SIDE_BY_SIDE(item)


def side_by_side(function, items, workers):
    """
    Return [function(item) for item in items], run side by side in up to workers processes.

    The first here, the others in workers forked from this process (function need not be
    picklable; its results must be), all on one BLAS thread: the same results for any number
    of workers.
    """
    global _SIDE_BY_SIDE
    items = list(items)
    _SIDE_BY_SIDE = function
    try:
        with _forked(min(workers, len(items)) - 1) as pool:
            if pool is None:
                return [function(item) for item in items]
            pending = [pool.apply_async(_call_in_worker, (item,)) for item in items[1:]]
            return [function(items[0])] + [result.get() for result in pending]
    finally:
        _SIDE_BY_SIDE = None


class _Fitter:
    """Makes and fits starts: here, or side by side in forked workers (the same answers)."""

    def __init__(self, problem, balance, iterations):
        self.problem, self.balance, self.iterations = problem, balance, iterations
        self.pool, self.last_start = None, None

    def run(self, job, progress=None):
        """Return a job's fitted x: ('fit', x0), ('ordered', seed) or ('random', seed)."""
        kind, value = job
        return self.fit(value) if kind == 'fit' else getattr(self, kind)(value, progress)

    def fit(self, x0):
        """Return start x0 fitted (on the torque balance first, with a first stage)."""
        self.last_start = x0
        if self.balance is not None:
            x0 = fit(self.balance, x0, self.iterations)
        return polish(self.problem, x0, self.iterations)

    def ordered(self, seed, progress=None):
        """Return an insertion-order start, its stages' tries drawn from seed, fitted."""
        x0 = insertion_order_start(self.problem, np.random.default_rng(seed),
                                   self.iterations, progress=progress)
        if not self.problem.free_segments:
            # Fields alone: the stages fitted every step from the state before it, as the
            # whole fit would (a step's equilibrium depends on its own field and that
            # state); only the limits that are not bounds are left to keep.
            self.last_start = x0
            return fit(self.problem, x0, self.iterations, gauss_newton=False)
        return self.fit(x0)

    def random(self, seed, progress=None):
        """Return a random start (directions uniform, fields within the limits), fitted."""
        problem, rng = self.problem, np.random.default_rng(seed)
        n_dir = len(problem.free_segments) * problem.angles_per_segment
        limit = problem.constraints.max_field_t or problem.constraints.max_total_field_t or \
            0.02
        directions = rng.uniform(-math.pi, math.pi, n_dir)
        if problem.angles_per_segment == 2:
            directions[1::2] *= 0.25  # elevations within +-45 deg
        fields = rng.uniform(-0.5, 0.5, problem.size - n_dir) * limit / MILLITESLA
        return self.fit(np.concatenate([directions, fields]))

    @contextlib.contextmanager
    def workers(self, count):
        """Run submitted starts in count - 1 forked processes while inside (1: here)."""
        global _WORKER_FITTER
        _WORKER_FITTER = self   # before the fork: the workers fit with this one's problem
        try:
            with _forked(count - 1) as self.pool:
                yield self
        finally:
            self.pool, _WORKER_FITTER = None, None

    def submit(self, job):
        """Return a callable that returns job's fitted x (from a worker, or run when called)."""
        if self.pool is None:
            return partial(self.run, job)
        handle = self.pool.apply_async(_fit_in_worker, (job,))

        def result():
            x, evaluations = handle.get()
            self.problem.evaluations += evaluations
            return x
        return result


def polish(problem, x0, iterations):
    """
    Return x fitted from x0 with every limit kept, the neighbour-angle limit approached.

    Where a neighbour-angle limit binds, least squares first weighs it as residuals of
    growing weight (NEIGHBOUR_WEIGHTS), so the start moves to within the limit along a path
    of good shapes; SLSQP then keeps it exactly. Straight from a start far past the limit,
    SLSQP often ended in a poor plan (pancreatic_duct: 0.8% of L became 13%). A start within
    the limit (a plan polished before, in a coarser model) goes straight to the last fit: the
    loosened ones would let it wander past the limit first.
    """
    if problem.constraints.max_neighbour_angle_rad is not None and problem.free_segments \
            and np.any(problem._neighbour_rows(x0, problem.unpack(x0)[0])[0]):   # past it
        for weight in NEIGHBOUR_WEIGHTS[:-1]:
            problem.neighbour_weight = weight
            try:
                x0 = fit(problem, x0, iterations, limits=False)
            finally:
                problem.neighbour_weight = NEIGHBOUR_WEIGHTS[-1]
    return fit(problem, x0, iterations)


class StartInterrupted(KeyboardInterrupt):
    """Ctrl-C during insertion_order_start, after some steps were fitted: x holds them."""

    def __init__(self, x, fitted):
        """Keep the unknowns x (the steps after the fitted ones hold the last field)."""
        super().__init__()
        self.x, self.fitted = x, fitted


def _limits(problem):
    """Return (lower, upper) arrays of the problem's bounds (inf where none)."""
    box = problem.bounds()
    return (np.array([-np.inf if b[0] is None else b[0] for b in box]),
            np.array([np.inf if b[1] is None else b[1] for b in box]))


def insertion_order_start(problem, rng, iterations=100, tries=4, progress=None):
    """
    Return a start built as the rig inserts: each step fits the segments it brings in.

    The tip goes in first: at every key step only the segments that enter with it and that
    step's field are unknown, the directions found before are held and the state is carried
    from the step before, so each stage is a small fit (a few random tries of the new
    directions, fewer once one fits within STAGE_GOOD). The whole problem is then polished
    from the result.

    :param progress: called with (steps fitted, steps, None) after each step
    :raises StartInterrupted: Ctrl-C once a step is fitted (KeyboardInterrupt before)
    """
    directions, _ = problem.unpack(np.zeros(problem.size))
    fields = []
    try:
        _fit_in_insertion_order(problem, rng, iterations, tries, directions, fields, progress)
    except KeyboardInterrupt:
        if not fields:
            raise
        raise StartInterrupted(problem.pack(directions, fields + [fields[-1]] * (
            len(problem.steps_m) - len(fields))), len(fields)) from None
    return problem.pack(directions, fields)


def _fit_in_insertion_order(problem, rng, iterations, tries, directions, fields, progress):
    """Fit insertion_order_start's stages: append each step's field, update directions."""
    model, c = problem.model, problem.constraints
    # Stages keep the per-axis field bounds only: the whole problem's fit (polish) keeps
    # every other limit (a stage's SLSQP took most of the time). Stages that weighed the
    # neighbour angle or the walls too made worse starts: greedy choices, dead ends later.
    bounds_only = replace(c, max_total_field_t=None, max_field_change_t=None,
                          max_neighbour_angle_rad=None)
    seen, start = set(), None
    field_t = np.zeros(3)
    for inserted_m, backbone_m, target in zip(problem.steps_m, problem.backbones_m,
                                              problem.targets):
        chain = model.chain(inserted_m)
        entering = set(chain.segment_index.tolist()) - seen
        seen |= entering
        new = sorted(entering & set(problem.free_segments))  # a held direction stays held
        best = None
        for _ in range(tries):
            stage = Problem(model, [inserted_m], [target], bounds_only,
                            directions=directions.copy(), start=start, free=new,
                            backbones_m=[backbone_m])
            guess = directions.copy()
            for i in stage.free_segments:
                guess[i] = _direction(rng.uniform(-math.pi, math.pi),
                                      0.0 if stage.angles_per_segment == 1 else
                                      rng.uniform(-0.5, 0.5))
            # Half the budget where the whole fit polishes the start; all of it where the
            # stages are the whole fit (fields alone).
            x = fit(stage, stage.pack(guess, [field_t]),
                    iterations // 2 if problem.free_segments else iterations, limits=False)
            value = stage.objective(x)[0]
            if best is None or value < best[0]:
                best = (value, stage, x)
            if not stage.free_segments or value < STAGE_GOOD:
                break
        _, stage, x = best
        stage_directions, stage_fields = stage.unpack(x)
        state = stage.simulate(x)[-1].state
        directions[:] = stage_directions  # a step counts once all of it is in
        field_t = stage_fields[0]
        fields.append(field_t)
        start = (state, inserted_m)
        if progress is not None:
            progress(len(fields), len(problem.steps_m), None)


def fit(problem, x0, iterations=100, limits=True, gauss_newton=True):
    """
    Return x after Gauss-Newton from x0, then SLSQP for the limits that are not bounds.

    Trust-region Gauss-Newton on the residuals with the per-axis field limits as bounds is
    the strong tool for this least-squares fit; SLSQP polishes only where total-field,
    field-change or neighbour-angle limits apply.

    :param iterations: model evaluations (Gauss-Newton) and SLSQP iterations: the budget
    :param limits: keep the limits that are not bounds (False: as residuals alone)
    :param gauss_newton: False: x0 is fitted already, keep the limits only
    """
    box = problem.bounds()
    lower, upper = _limits(problem)
    cache = {}

    def fun(x):
        cache['x'], cache['value'] = x.copy(), problem.residuals(x)
        return cache['value'][0]

    def jac(x):
        if 'x' not in cache or not np.array_equal(cache['x'], x):
            fun(x)
        return cache['value'][1]

    x = np.clip(x0, lower, upper)
    if gauss_newton:
        x = least_squares(fun, x, jac=jac, bounds=(lower, upper), method='trf',
                          max_nfev=iterations, xtol=1e-12, ftol=1e-14, gtol=1e-12).x
    constraints = problem.inequalities() if limits else []
    # A least-squares minimum that keeps every limit is the constrained one as well.
    if constraints and min(np.min(c['fun'](x)) for c in constraints) < 0:
        x = minimize(problem.objective, x, jac=True, method='SLSQP', bounds=box,
                     constraints=constraints,
                     options={'maxiter': iterations, 'ftol': 1e-14}).x
    return x
