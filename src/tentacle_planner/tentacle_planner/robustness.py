"""
How a plan fares when the real tentacle or rig is not the model: perturbed models.

The thesis puts its remaining navigation error on an imprecisely placed insertion point
and on model error. Each perturbation below is a model of the same knobs with one thing
changed (mismatch.perturbed: the knobs a scene's mismatch block turns for the simulated
rig); a plan (its magnetisation and fields) is played in each, warm-started along the
insertion, and its shape error per step reported. ``RobustProblem`` plans against all of
them at once: its residuals stack every perturbed model's, so the fit minimises the sum of
their squared errors, which bounds the worst one (reported beside the nominal). Where the
scene has walls, those residuals include each perturbed body's keep-off: on the pancreatic
duct they are most of the sum, and the robust plan keeps every perturbed body off the walls
(the nominal plan runs up to 0.41 mm into them) at a price in shape error.
"""

from dataclasses import replace
import math

import numpy as np
from tentacle_model.model import TentacleModel
from tentacle_planner.mismatch import perturbed
from tentacle_planner.optimise import Problem

PERTURBATIONS = (
    ('stiffness x0.8', {'stiffness': 0.8}),
    ('stiffness x1.2', {'stiffness': 1.2}),
    ('remanence x0.9', {'remanence': 0.9}),
    ('remanence x1.1', {'remanence': 1.1}),
    ('insertion point 0.5 mm sideways', {'sideways_m': 0.5e-3}),
    ('base direction turned 2 deg', {'turn_rad': math.radians(2.0)}),
)
ON_THE_RIG = "the scene's mismatch"   # the report's row of the simulated rig (on_the_rig)


def variant(model, spec):
    """Return a TentacleModel of the same knobs for another spec."""
    return TentacleModel(spec, dof=model.dof, sublinks=model.sublinks,
                         gravity_m_s2=model.gravity_m_s2, dipoles=model.dipoles,
                         backbone_m=model.backbone_m, tol=model.tol,
                         max_iterations=model.max_iterations)


def perturbed_problems(problem):
    """Return [(name, Problem)]: the nominal problem first, then each perturbation's."""
    out = [('nominal', problem)]
    for name, change in PERTURBATIONS:
        model = variant(problem.model, perturbed(problem.model.spec, **change))
        out.append((name, Problem(model, problem.steps_m, problem.targets,
                                  problem.constraints, problem.fixed_directions,
                                  problem.start, backbones_m=problem.backbones_m,
                                  keep_off=problem.keep_off)))
    return out


def on_the_rig(problem, mismatch):
    """
    Return [(name, Problem, coils)]: the plan's problem on a scene's mismatched rig, or [].

    The tentacle as the scene's ``mismatch`` block makes the simulated rig's (softer, less
    magnetised, its insertion point moved and turned) and ``coils`` (3,), the field the rig
    makes per field commanded on each axis (its actuation matrix's columns scaled).
    """
    if mismatch.describe() == 'none':
        return []
    model = variant(problem.model, mismatch.tentacle(problem.model.spec))
    return [(f'{ON_THE_RIG} ({mismatch.describe()})',
             Problem(model, problem.steps_m, problem.targets, problem.constraints,
                     problem.fixed_directions, problem.start, backbones_m=problem.backbones_m,
                     keep_off=problem.keep_off),
             np.asarray(mismatch.actuation_matrix_factor, dtype=float))]


def report(problems, plan, error=None, rig=()):
    """
    Return [(name, shape RMS per step, shape RMS over the steps, deepest contact)], m.

    The deepest contact is how far the plan's body runs into the problem's obstacles and
    walls in that model (0: it keeps off; Problem.deepest_contact_m).

    :param problems: perturbed_problems(...)
    :param error: step -> shape RMS (m); default the optimiser's (joints and tip)
    :param rig: on_the_rig(...): its rows last, each played with its coils' fields
    """
    rows = []
    for name, problem, coils in [(n, p, 1.0) for n, p in problems] + list(rig):
        rows.append(_row(name, problem, plan, plan.fields_t * coils, error))
    return rows


def _row(name, problem, plan, fields_t, error):
    """Return report's row of a plan's directions and these fields played in a problem."""
    played = problem.plan(problem.pack(plan.directions, fields_t))
    per_step = [s.shape_rms_m if error is None else error(s) for s in played.steps]
    return (name, per_step, float(np.sqrt(np.mean(np.square(per_step)))),
            problem.deepest_contact_m(played))


def played_densely(rig, plan, steps, error):
    """
    Return report's rows for on_the_rig's: the plan's every playback step, as the rig runs it.

    The rig plays each dense step's field in turn, each from the equilibrium of the step
    before; the key steps alone (report) start each step from the key step before, and can
    end on another equilibrium where the body is bistable.

    :param rig: on_the_rig(...)
    :param steps: the plan's dense playback Steps (their fields and inserted lengths)
    :param error: step -> shape RMS (m), against the path (the dense steps are played
        without targets of their own)
    """
    rows = []
    lengths = [s.inserted_m for s in steps]
    fields = np.array([s.field_t for s in steps])
    for name, problem, coils in rig:
        model = problem.model
        dense = Problem(model, lengths, [np.zeros((model.chain(length).size + 1, 3))
                                         for length in lengths],
                        problem.constraints, problem.fixed_directions, problem.start,
                        backbones_m=[s.backbone_m for s in steps], keep_off=problem.keep_off)
        rows.append(_row(f'{name}, every playback step', dense, plan, fields * coils, error))
    return rows


class RobustProblem:
    """Every perturbed model's residuals at once, for one set of unknowns."""

    def __init__(self, problems):
        """Take perturbed_problems(...): the nominal first."""
        self.named = problems
        self.nominal = problems[0][1]
        self.evaluations = 0

    def __getattr__(self, name):
        # The unknowns, bounds, limits and plans are the nominal problem's.
        return getattr(self.nominal, name)

    def residuals(self, x):
        """Return the stacked residuals and Jacobians of every model."""
        self.evaluations += 1
        parts = [p.residuals(x) for _, p in self.named]
        return np.concatenate([r for r, _ in parts]), np.vstack([j for _, j in parts])

    def objective(self, x):
        """Return (sum of every model's objective, its gradient)."""
        r, jac = self.residuals(x)
        return float(r @ r), 2 * jac.T @ r

    def plan(self, x, flags=()):
        """Return the nominal Plan at x, its objective the robust one."""
        r = np.concatenate([p.residuals(x, jacobian=False)[0] for _, p in self.named])
        return replace(self.nominal.plan(x, flags), objective=float(r @ r))
