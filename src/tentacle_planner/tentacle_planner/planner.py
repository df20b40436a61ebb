"""
Plan a scene: magnetisation and fields, verified, played back densely, tested for robustness.

The Python API behind ``tentacle-plan``: ``plan_scene(load_scene(file))`` returns a
SceneResult with the key-step plan, the dense playback, the robustness report (and, with
``robust=True``, the plan made against every perturbed model with its own report), and the
re-check in the scene's own model where planning left a term out (magnet-to-magnet
interaction is planned without and verified with).
"""

from dataclasses import dataclass, field, replace
from functools import partial
import math
import os

import numpy as np
from tentacle_model import statics
from tentacle_model.chain import discretise
from tentacle_planner import paths
from tentacle_planner.clearance import clearance
from tentacle_planner.optimise import (clean, Constraints, KeepOff, leading, optimise, Plan,
                                       polish, Problem, side_by_side)
from tentacle_planner.playback import playback
from tentacle_planner.robustness import (on_the_rig, perturbed_problems, played_densely,
                                         report, RobustProblem)
from tentacle_planner.search_defaults import (DEFAULT_ITERATIONS, DEFAULT_MIN_GAIN,
                                              DEFAULT_STARTS)

HIGHER_FIDELITY_SUBLINKS = 4  # sub-links per planning link in the re-check
REFINE_TOLERANCE = 0.1        # the re-check may be this much (of the error) worse: confirmed
WORKERS = 2                   # processes fitting starts side by side, at most
REFINED = 2                   # plans refine polishes and re-checks side by side, a round


def default_workers():
    """Return WORKERS, or the number of cores this process may use if fewer."""
    return max(1, min(WORKERS, len(os.sched_getaffinity(0))))


@dataclass(frozen=True)
class SceneResult:
    """What plan_scene found; shape errors in m."""

    scene: object
    plan: Plan                      # the plan to play (robust if asked for)
    nominal_plan: Plan              # planned against the nominal model
    robust_plan: Plan | None
    playback_steps: list            # dense Steps, or [] without playback_step_m
    robustness: list                # [(perturbation, per-step RMS, RMS, contact)]: nominal plan
    robust_robustness: list         # the same for the robust plan, or []
    verification: list              # [(what, RMS)]: the plan re-checked in fuller models
    flags: list = field(default_factory=list)
    interrupted: bool = False
    planning_model: object = None   # the ModelSettings the plan was made in (None: the scene's)


def constraints_of(scene, tip_driven=False):
    """Return the optimiser's Constraints for a scene's coil and magnetisation limits."""
    m = scene.magnetisation
    return Constraints(
        max_field_t=scene.coil.max_field_t, max_total_field_t=scene.coil.max_total_field_t,
        max_field_change_t=scene.coil.max_field_change_t, planar_magnetisation=m.planar,
        max_neighbour_angle_rad=None if m.max_neighbour_angle_deg is None else math.radians(
            m.max_neighbour_angle_deg),
        distal_axial=m.distal_axial, tip_driven=tip_driven)


def key_steps(scene, model):
    """Return (inserted lengths, backbone reaches, targets) of a scene's key steps, m."""
    steps = list(scene.insertion_steps_m)
    backbones = list(scene.backbone_steps_m or [0.0] * len(steps))
    targets = [paths.targets(scene.target_path(s, b), model.chain(s), s)
               for s, b in zip(steps, backbones)]
    return steps, backbones, targets


def keep_off(scene):
    """Return the scene's KeepOff: its obstacles and walls, and its clearance margin."""
    return KeepOff(scene.obstacles, scene.walls, scene.clearance_margin_m)


def problem_of(scene, tip_driven=False):
    """
    Return the Problem of a scene's key steps, in its planning model, kept off its walls.

    The scene's model, except that magnet-to-magnet interaction is left out where the
    magnetisation is planned (the moment sensitivity does not include it): such plans are
    verified with it (recheck). Fields alone, for a given magnetisation, are planned with it.
    """
    given = scene.magnetisation.given and not tip_driven
    model = scene.tentacle_model(dipoles=scene.model.dipoles and given)
    steps, backbones, targets = key_steps(scene, model)
    return Problem(model, steps, targets, constraints_of(scene, tip_driven),
                   directions=scene.own_directions() if given else None,
                   backbones_m=backbones, keep_off=keep_off(scene))


def shape_rms(scene, steps):
    """Return the shape error over steps, m: DESIGN.md's (paths.shape_error), RMS."""
    return float(np.sqrt(np.mean([scene.shape_error(step)[0] ** 2 for step in steps])))


def step_clearance(scene, step):
    """Return (gap, what): how far a Step's body keeps off the scene's obstacles, m."""
    radii = step.link_radii_m
    if radii is None:   # a step of the scene's own model
        chain = discretise(scene.tentacle, step.inserted_m, scene.model.sublinks)
        radii = [scene.tentacle.segments[i].radius_m for i in chain.segment_index]
    return clearance(step.points_m, radii, scene.obstacles, scene.walls)


def contact_flags(scene, steps):
    """Return a flag for every step whose body touches an obstacle or wall."""
    flags = []
    for step in steps:
        gap, what = step_clearance(scene, step)
        if gap <= 0:
            flags.append(f'the body touches {what} at {step.inserted_m * 1e3:.1f} mm inserted '
                         f'({-gap * 1e3:.2f} mm into it)')
    return flags


def deepest_contact_m(scene, steps):
    """Return how far the body of any Step runs into the scene's obstacles and walls, m."""
    return max([0.0] + [-step_clearance(scene, step)[0] for step in steps])


def least_contact_flag(scene, steps):
    """Return [a flag] where any step's body touches: the deepest contact, the least found."""
    gaps = [step_clearance(scene, step) + (step.inserted_m,) for step in steps]
    gap, what, inserted_m = min(gaps, key=lambda g: g[0], default=(math.inf, None, None))
    if gap > 0:
        return []
    return [f'no plan found keeps the body off every obstacle and wall: the least penetration '
            f'found is {-gap * 1e3:.2f} mm, into {what} at {inserted_m * 1e3:.1f} mm inserted']


def higher_fidelity_sublinks(scene):
    """
    Return the re-check's sub-links per segment (None: no more than the scene's fit).

    The most, up to HIGHER_FIDELITY_SUBLINKS times the scene's, that the solver's size
    limits allow with 3-DoF joints and the magnets' interaction.
    """
    for sublinks in range(scene.model.sublinks * HIGHER_FIDELITY_SUBLINKS,
                          scene.model.sublinks, -1):
        chain = discretise(scene.tentacle, scene.insertion_steps_m[-1], sublinks)
        try:
            statics.check_size(chain.size, 3, chain.interacting_pair_count())
        except statics.ProblemTooLarge:
            continue
        return sublinks
    return None


def finer_problem(scene, problem, sublinks):
    """Return the Problem of a scene's key steps in its planning model with more sub-links."""
    model = scene.tentacle_model(sublinks=sublinks, dipoles=problem.model.dipoles)
    steps, backbones, targets = key_steps(scene, model)
    return Problem(model, steps, targets, problem.constraints, problem.fixed_directions,
                   backbones_m=backbones, keep_off=problem.keep_off)


def refinements(planning, finest):
    """Return the sub-links to polish in, in turn: doubling from planning's, up to finest."""
    out = []
    while planning < finest:
        planning = min(2 * planning, finest)
        out.append(planning)
    return out


def refined(scene, problem, plans, iterations, workers=1):
    """
    Yield (problem, plan, re-check) of plans refined, the best re-checked first.

    The re-check is recheck(scene, plan) of the plan yielded. Refined: the plan is polished
    with twice the sub-links, kept where it fits that model better, and re-checked; then
    again with twice those (up to the re-check's) until a model is confirmed: the plan
    re-checked at higher fidelity no worse than in that model by more than REFINE_TOLERANCE
    of its error (and 0.1% of L). The first polish is not skipped where the planning model
    is confirmed already: the search's budget leaves its plans short of their best
    (pancreatic duct, seeds 0-9: median re-checked 0.86% of L, 0.81% polished once). The
    plan, its dense playback and its robustness are then the finer model's.

    Plans are refined REFINED at a time, side by side in up to workers processes, best
    first, until one is without flags and clear of every wall (an exact fit in the planning
    model may run into a wall in the finer one). Of those refined, the one without flags,
    running least deep into a wall and then of least re-checked error comes first: the
    search's best in the planning model is not always the best re-checked (ch3_b: 0.69 mm
    against 0.13 mm). Asked for another (its dense playback touched), every plan is refined
    and the next in that order comes.
    """
    finest = higher_fidelity_sublinks(scene)
    if finest is None or not problem.free_segments:
        # Fields alone (a given magnetisation, ch6_coiling): not yet; the coiling strip's
        # finer model takes 8 times as long to simulate (27 ms a solve for sim_node).
        for plan in plans:
            yield problem, plan, None
        return
    done, pending, asked_again = [], list(plans), False
    while done or pending:
        # the first: once one is clean; asked again: of them all
        if pending and (asked_again or not any(clean(entry[3]) for entry in done)):
            done += side_by_side(partial(_refined, scene, problem, finest, iterations),
                                 pending[:REFINED], workers)
            pending = pending[REFINED:]
            continue
        sublinks, plan, checked, _ = done.pop(min(range(len(done)),
                                                  key=lambda i: done[i][3]))
        yield (problem if sublinks == problem.model.sublinks else
               finer_problem(scene, problem, sublinks)), plan, checked
        asked_again = True


def _refined(scene, problem, finest, iterations, plan):
    """Return (sub-links, plan, re-check, rank) of one plan refined as refined() says."""
    checked = None
    for sublinks in refinements(problem.model.sublinks, finest):
        if checked is not None:   # not before the first polish: that one always comes
            planned, rechecked = shape_rms(scene, plan.steps), checked[0][-1][1]
            if rechecked - planned <= max(REFINE_TOLERANCE * planned,
                                          1e-3 * scene.tentacle.length_m):
                break
        problem = finer_problem(scene, problem, sublinks)
        x0 = problem.pack(plan.directions, plan.fields_t)
        x = polish(problem, x0, iterations)
        plan = problem.plan(x if _objective(problem, x) < _objective(problem, x0) else x0)
        checked = recheck(scene, plan)
    checked = recheck(scene, plan) if checked is None else checked
    return (problem.model.sublinks, plan, checked,
            problem.rank(plan, checked[0][-1][1], flags=len(checked[1])))


def _objective(problem, x):
    r = problem.residuals(x, jacobian=False)[0]
    return float(r @ r)


def fuller_models(scene):
    """
    Return [(what, model options)]: the models a plan is re-checked in.

    The scene's own model when planning left a term out (magnet-to-magnet interaction is
    planned without), and always a higher-fidelity one: HIGHER_FIDELITY_SUBLINKS times the
    sub-links, 3-DoF joints (twist and out-of-plane bending), the scene's gravity and the
    interaction, as large as the solver's size limits allow.
    """
    planned_without = scene.model.dipoles and not scene.magnetisation.given
    out = [('the scene model with magnet-to-magnet interaction', {})] if planned_without \
        else []
    sublinks = higher_fidelity_sublinks(scene)
    if sublinks is not None:
        out.append((f'higher fidelity: {sublinks} sub-links per segment, 3-DoF joints, '
                    'magnet-to-magnet interaction', {'sublinks': sublinks, 'dof': 3,
                                                     'dipoles': True}))
    return out


def recheck(scene, plan):
    """
    Return ([(what, shape RMS m)], flags): the plan's key steps played in fuller_models.

    The same magnetisation and fields, warm-started along the insertion as the rig runs
    them; the shape error is the project's (paths.shape_error) over the key steps.
    """
    rows, flags = [], []
    for what, options in fuller_models(scene):
        model = scene.tentacle_model(**options)
        steps, backbones, targets = key_steps(scene, model)
        problem = Problem(model, steps, targets, backbones_m=backbones)
        played = problem.plan(problem.pack(plan.directions, plan.fields_t))
        rows.append((what, shape_rms(scene, played.steps)))
        flags += [f'{flag} ({what.split(":")[0]})' for flag in played.flags]
    return rows, flags


def plan_scene(scene, *, seed=0, starts=DEFAULT_STARTS, iterations=DEFAULT_ITERATIONS,
               min_gain=DEFAULT_MIN_GAIN, tip_driven=False, robust=False, progress=None,
               first_stage=False, workers=None):
    """
    Return the SceneResult of a scene.

    :param seed: seeds the multi-start: the same seed gives the same plan
    :param starts: random starts of the multi-start, at most
    :param iterations: model evaluations per start (the budget)
    :param min_gain: end the multi-start once a round of starts gains less than this
        fraction of the objective (None or 0: every start, the exhaustive search)
    :param workers: processes fitting starts side by side (default: WORKERS, or the cores
        this process may use, if fewer); the plan is the same for any number
    :param tip_driven: the baseline: every magnetisation axial, fields only
    :param robust: plan against the worst of the perturbed models, not the nominal one
    :param progress: called with (stage, done, total, best objective)
    :param first_stage: fit each start on the thesis' torque balance first (balance.py)

    Ctrl-C (KeyboardInterrupt) in the search returns the best plan so far, marked
    interrupted; after a plan exists, Ctrl-C in any later phase (the robust plan, dense
    playback, the robustness report, the re-check) skips that phase and the rest and
    returns the plan with a flag that says what was left out. Before any plan exists
    (setting up, the first step of the first start), KeyboardInterrupt propagates.
    """
    problem = problem_of(scene, tip_driven)

    def report_progress(stage):
        return None if progress is None else (
            lambda done, total, best: progress(stage, done, total, best))

    workers = default_workers() if workers is None else workers
    found = leading(problem, keep=starts, seed=seed, starts=starts, iterations=iterations,
                    progress=report_progress('plan'), first_stage=first_stage,
                    min_gain=min_gain, workers=workers)
    nominal = found[0]
    try:
        return _after_search(scene, problem, found, seed, iterations, robust,
                             report_progress, workers)
    except KeyboardInterrupt:  # between two phases: the plan alone
        return SceneResult(scene, nominal, nominal, None, [], [], [], [],
                           list(nominal.flags) + ['interrupted: left out everything after '
                                                  'the search'], True)


def _after_search(scene, problem, found, seed, iterations, robust, report_progress, workers):
    """Return plan_scene's SceneResult from the search's best plans: the phases after it."""
    nominal = found[0]

    def error(step):
        return scene.shape_error(step)[0]

    interrupted = nominal.interrupted
    skipped = []

    def phase(what, run, otherwise):
        """Return run(), or otherwise once interrupted (now, or in an earlier phase)."""
        nonlocal interrupted
        if not interrupted:
            try:
                return run()
            except KeyboardInterrupt:
                interrupted = True
        skipped.append(what)
        return otherwise

    def dense_playback(problem, plan):
        """Return (steps, flags) of a plan played every playback step in problem's model."""
        steps, dense_flags = playback(
            problem.model, plan, lambda chain, inserted: paths.targets(scene.path, chain,
                                                                       inserted),
            scene.playback_step_m, problem.constraints, progress=report_progress('playback'),
            keep_off=problem.keep_off)
        key = {round(s.inserted_m, 12) for s in plan.steps}
        return steps, dense_flags + contact_flags(
            scene, [s for s in steps if round(s.inserted_m, 12) not in key])

    candidates = refined(scene, problem, found, iterations, workers)
    problem, nominal, checked = phase('the polish in the finer model',
                                      lambda: next(candidates), (problem, nominal, None))
    played = None   # the nominal plan's (dense steps, flags), once played
    if scene.playback_step_m and not robust:
        def played_clear():
            """
            Return the first refined plan whose playback keeps off, flagless, with it.

            Or else the one whose body runs least deep into a wall: a plan clear at its key
            steps may touch between them (bile_duct: 0.91 mm at 12 mm, once).
            """
            entry, best = (problem, nominal, checked), None
            while entry is not None:
                dense = dense_playback(*entry[:2])
                order = (deepest_contact_m(scene, list(entry[1].steps) + dense[0]),
                         len(dense[1]))
                if best is None or order < best[0]:
                    best = order, entry + (dense,)
                if not dense[1]:
                    break
                entry = next(candidates, None)
            return best[1]
        problem, nominal, checked, played = phase(
            'dense playback (key steps only)', played_clear,
            (problem, nominal, checked, ([], [])))
    problems = phase('the robustness report', lambda: perturbed_problems(problem), [])
    rig = on_the_rig(problem, scene.mismatch)
    robust_plan, robust_rows = None, []
    if robust:
        robust_plan = phase('the robust plan', lambda: optimise(
            RobustProblem(problems), seed=seed, starts=0, iterations=iterations,
            initial=problem.pack(nominal.directions, nominal.fields_t),
            progress=report_progress('robust')), None)
        if robust_plan is not None and robust_plan.interrupted:
            interrupted, robust_plan = True, None  # the nominal plan: it is complete
            skipped.append('the robust plan')
        if robust_plan is not None:
            robust_rows = phase("the robust plan's robustness report",
                                lambda: report(problems, robust_plan, error, rig), [])
    plan = robust_plan or nominal
    flags = list(plan.flags) + contact_flags(scene, plan.steps)
    if scene.playback_step_m and played is None:
        played = phase('dense playback (key steps only)',
                       lambda: dense_playback(problem, plan), ([], []))
    dense, dense_flags = played or ([], [])
    flags += dense_flags
    flags = least_contact_flag(scene, list(plan.steps) + dense) + flags
    robustness = phase('the robustness report', lambda: report(problems, nominal, error, rig),
                       [])
    if dense and (robustness if robust_plan is None else robust_rows):
        # the plan played: its own rows gain the rig's row for every playback step
        (robustness if robust_plan is None else robust_rows).extend(phase(
            'the robustness report', lambda: played_densely(rig, plan, dense, error), []))
    verification, recheck_flags = phase(
        'the re-check in fuller models', lambda: checked if checked is not None and (
            plan is nominal) else recheck(scene, plan), ([], []))
    flags += recheck_flags
    if skipped:
        flags.append('interrupted: left out ' + ', '.join(dict.fromkeys(skipped)))
    return SceneResult(scene, plan, nominal, robust_plan, dense, robustness,
                       robust_rows, verification, flags, interrupted,
                       replace(scene.model, sublinks=problem.model.sublinks))


def magnetisation_angles_deg(directions):
    """Return (azimuth in the link x-y plane, elevation out of it) per segment, degrees."""
    d = np.asarray(directions, dtype=float)
    return np.degrees(np.column_stack([np.arctan2(d[:, 1], d[:, 0]),
                                       np.arcsin(np.clip(d[:, 2], -1.0, 1.0))]))
