"""
Plan a scene: magnetisation and fields, verified, played back densely, tested for robustness.

The Python API behind ``tentacle-plan``: ``plan_scene(load_scene(file))`` returns a
SceneResult with the key-step plan, the dense playback, the robustness report (and, with
``robust=True``, the plan made against every perturbed model with its own report), and the
re-check in the scene's own model where planning left a term out (magnet-to-magnet
interaction is planned without and verified with).
"""

from dataclasses import dataclass, field
import math

import numpy as np
from tentacle_planner import paths
from tentacle_planner.optimise import Constraints, optimise, Plan, Problem
from tentacle_planner.playback import playback
from tentacle_planner.robustness import perturbed_problems, report, RobustProblem


@dataclass(frozen=True)
class SceneResult:
    """What plan_scene found; shape errors in m."""

    scene: object
    plan: Plan                      # the plan to play (robust if asked for)
    nominal_plan: Plan              # planned against the nominal model
    robust_plan: Plan | None
    playback_steps: list            # dense Steps, or [] without playback_step_m
    robustness: list                # [(perturbation, per-step RMS, RMS)] of the nominal plan
    robust_robustness: list         # the same for the robust plan, or []
    verification: list              # [(what, RMS)] in the scene's full model, if it differs
    flags: list = field(default_factory=list)
    interrupted: bool = False


def constraints_of(scene, tip_driven=False):
    """Return the optimiser's Constraints for a scene's coil and magnetisation limits."""
    m = scene.magnetisation
    return Constraints(
        max_field_t=scene.coil.max_field_t, max_total_field_t=scene.coil.max_total_field_t,
        max_field_change_t=scene.coil.max_field_change_t, planar_magnetisation=m.planar,
        max_neighbour_angle_rad=None if m.max_neighbour_angle_deg is None else math.radians(
            m.max_neighbour_angle_deg),
        distal_axial=m.distal_axial, tip_driven=tip_driven)


def problem_of(scene, tip_driven=False):
    """Return the Problem of a scene's key steps, in its planning model (no dipoles)."""
    model = scene.tentacle_model(dipoles=False)
    steps = list(scene.insertion_steps_m)
    targets = [paths.targets(scene.path, model.chain(s), s) for s in steps]
    return Problem(model, steps, targets, constraints_of(scene, tip_driven))


def plan_scene(scene, *, seed=0, starts=8, iterations=100, tip_driven=False, robust=False,
               progress=None):
    """
    Return the SceneResult of a scene.

    :param seed: seeds the multi-start: the same seed gives the same plan
    :param starts: random starts of the multi-start
    :param iterations: model evaluations per start (the budget)
    :param tip_driven: the baseline: every magnetisation axial, fields only
    :param robust: plan against the worst of the perturbed models, not the nominal one
    :param progress: called with (stage, done, total, best objective)
    """
    problem = problem_of(scene, tip_driven)

    def error(step):
        return paths.shape_error(step.points_m, scene.path, step.inserted_m)[0]

    def report_progress(stage):
        return None if progress is None else (
            lambda done, total, best: progress(stage, done, total, best))

    nominal = optimise(problem, seed=seed, starts=starts, iterations=iterations,
                       progress=report_progress('plan'))
    interrupted = nominal.interrupted
    problems = perturbed_problems(problem)
    robust_plan, robust_rows = None, []
    if robust and not interrupted:
        robust_plan = optimise(RobustProblem(problems), seed=seed, starts=0,
                               iterations=iterations,
                               initial=problem.pack(nominal.directions, nominal.fields_t),
                               progress=report_progress('robust'))
        interrupted = robust_plan.interrupted
        robust_rows = report(problems, robust_plan, error)
    plan = robust_plan or nominal
    flags = list(plan.flags)
    dense = []
    if scene.playback_step_m and not interrupted:
        dense, dense_flags = playback(
            problem.model, plan, lambda chain, inserted: paths.targets(scene.path, chain,
                                                                       inserted),
            scene.playback_step_m, problem.constraints)
        flags += dense_flags
    verification = []
    if scene.model.dipoles:
        full = Problem(scene.tentacle_model(), problem.steps_m, problem.targets,
                       problem.constraints)
        played = full.plan(full.pack(plan.directions, plan.fields_t))
        verification.append(('with magnet-to-magnet interaction', float(np.sqrt(np.mean(
            [error(step) ** 2 for step in played.steps])))))
        flags += [f'{f} (with magnet-to-magnet interaction)' for f in played.flags]
    return SceneResult(scene, plan, nominal, robust_plan, dense,
                       report(problems, nominal, error),
                       robust_rows, verification, flags, interrupted)


def magnetisation_angles_deg(directions):
    """Return (azimuth in the link x-y plane, elevation out of it) per segment, degrees."""
    d = np.asarray(directions, dtype=float)
    return np.degrees(np.column_stack([np.arctan2(d[:, 1], d[:, 0]),
                                       np.arcsin(np.clip(d[:, 2], -1.0, 1.0))]))
