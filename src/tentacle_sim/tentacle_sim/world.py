"""
The simulated rig's physics: the body in the field the coils really make, where it really is.

``World.step(currents_a, inserter_m, backbone_m)`` takes what the emulated devices hold at one
moment (the coil currents their supplies output, slew and R-L lag included; the stages' true
positions) and returns the ``Body``: the equilibrium of the tentacle as the rig has it (the
scene's ``mismatch`` applied: moduli and magnetisation scaled, the insertion pose moved,
each coil's column of the actuation matrix scaled) in the scene's own model (its ``model`` block: a
planar scene runs the planar model), warm-started from the previous step's state and cut at
a per-step time budget (the next step solves on from there). Contact with the phantom is
detected, not modelled: the body passes through a wall, and the report says how deep.
Frames: every point is in ``coils``, metres.
"""

import dataclasses
from dataclasses import dataclass
import time

import numpy as np
from tentacle_common import frames
from tentacle_model.model import TentacleModel
from tentacle_planner.clearance import link_gaps


@dataclass(frozen=True)
class Body:
    """The body at one moment, and what put it there."""

    points_m: np.ndarray     # (n + 1, 3) joints and tip, base first, frame coils, m
    field_t: np.ndarray      # (3,) the field it feels, T, frame coils
    inserted_m: float        # the length past the insertion point, m
    backbone_m: float        # the backbone's reach past the insertion point, m
    converged: bool          # False: the descent was cut at the budget (it goes on next step)
    reason: str              # the solver's word on it
    contacts: int            # links that cross a wall or an obstacle (radius included)
    contact_depth_m: float   # the deepest of those crossings, m (0 without contact)
    solve_s: float           # wall time of the solve, s


def made_to_plan(scene, schedule):
    """
    Return the scene with the tentacle made to a schedule's plan, in the plan's sub-links.

    Its planned magnetisation in place of the tentacle file's, simulated with as many
    sub-links per segment as the plan was made in (the planner may polish a plan finer than
    the scene's model: planner.refined).

    :param schedule: a schedule_file.Schedule
    """
    model = dataclasses.replace(scene.model, sublinks=schedule.model.sublinks)
    return dataclasses.replace(scene, tentacle=schedule.tentacle_spec(), model=model)


class World:
    """One scene's tentacle in the simulated rig."""

    def __init__(self, scene, actuation_matrix_t_per_a, *, insertion_offset_m=0.0,
                 time_budget_s=0.02):
        """
        Build the true tentacle and coils.

        :param scene: a tentacle_planner.scene.Scene (its tentacle, model, phantom, mismatch)
        :param actuation_matrix_t_per_a: (9,) or (3, 3) the coils' nominal B = A I, T/A
        :param insertion_offset_m: the inserter stage's position with the tip at the
            insertion point, m (frames.inserted_length_m)
        :param time_budget_s: the most one step's solve may take, s
        """
        self.scene = scene
        self.spec = scene.mismatch.tentacle(scene.tentacle)
        self.model = TentacleModel(self.spec, **scene.model.as_options())
        self.actuation = scene.mismatch.actuation_matrix(actuation_matrix_t_per_a)
        self.insertion_offset_m = float(insertion_offset_m)
        self.time_budget_s = float(time_budget_s)
        self.has_backbone = self.spec.backbone is not None
        self._state, self._inserted = None, None

    def field_t(self, currents_a):
        """Return the field (3,), T, frame coils, that coil currents (3,), A, make."""
        return self.actuation @ np.asarray(currents_a, dtype=float)

    def inserted_m(self, inserter_m):
        """Return the inserted length, m, at an inserter stage position, m, within [0, L]."""
        return min(frames.inserted_length_m(inserter_m, self.insertion_offset_m),
                   self.spec.length_m)

    def step(self, currents_a, inserter_m, backbone_m=0.0):
        """
        Return the Body in the field of these currents at these stage positions.

        :param currents_a: (3,) the coil currents now, A
        :param inserter_m: the inserter stage's true position, m
        :param backbone_m: the backbone stage's true position, m (its reach past the
            insertion point; ignored for a tentacle without a backbone)
        """
        field = self.field_t(currents_a)
        inserted = self.inserted_m(inserter_m)
        backbone = min(max(float(backbone_m), 0.0), inserted) if self.has_backbone else 0.0
        start = None
        if self._state is not None:
            start = self.model.carry(self._state, self._inserted, inserted)
        t0 = time.perf_counter()
        solution = self.model.solve(inserted, field, start, backbone_m=backbone,
                                    time_limit_s=self.time_budget_s)
        solve_s = time.perf_counter() - t0
        eq = solution.equilibrium
        if np.all(np.isfinite(solution.state)):
            self._state, self._inserted = solution.state, inserted
        else:  # nothing to go on from: the next step starts straight
            self._state, self._inserted = None, None
        contacts, depth = self.contact(solution.points_m, solution.chain)
        return Body(solution.points_m, field, inserted, backbone, eq.converged, eq.reason,
                    contacts, depth, solve_s)

    def contact(self, points_m, chain):
        """Return (links crossing a wall or obstacle, the deepest crossing, m)."""
        if not (self.scene.obstacles or self.scene.walls) or chain.size == 0:
            return 0, 0.0
        if not np.all(np.isfinite(points_m)):
            return 0, 0.0
        radii = [self.spec.segments[i].radius_m for i in chain.segment_index]
        gaps = link_gaps(points_m, radii, self.scene.obstacles, self.scene.walls)
        least = np.min(gaps, axis=1)
        crossing = int(np.count_nonzero(least < 0))
        return crossing, float(-least.min()) if crossing else 0.0

    def body_width_m(self):
        """Return the body's widest section in the base plane, m (what the camera sees)."""
        return max(s.width_m for s in self.spec.segments)

    def magnet_ranges_m(self, inserted_m):
        """
        Return the magnetised stretches' (start, end) arc lengths past the insertion point.

        Neighbouring magnetised segments make one stretch (the renderer draws each in turn).
        """
        base = self.spec.length_m - inserted_m  # material coordinate at the insertion point
        ranges, start = [], 0.0
        for segment in self.spec.segments:
            end = start + segment.length_m
            if np.any(segment.magnetisation_a_per_m) and end > base:
                first = max(start - base, 0.0)
                if ranges and abs(ranges[-1][1] - first) < 1e-12:
                    ranges[-1] = (ranges[-1][0], end - base)
                else:
                    ranges.append((first, end - base))
            start = end
        return ranges
