"""
Dense playback: a field for every small insertion step, the magnetisation held fixed.

The rig inserts 1 mm at a time at about 2 Hz (thesis 5.3.3) while a plan has a few key steps.
Between them, every ``playback_step_m`` of insertion gets its own field, fitted for that
partial insertion with the plan's magnetisation, warm-started from the step before it as the
rig runs it (the state carried along the insertion), starting from the field interpolated
between the key steps. Each step is verified in the forward model and flagged if it is not a
stable converged equilibrium.
"""

import numpy as np
from tentacle_planner.optimise import fit, Problem


def dense_lengths(key_steps_m, step_m):
    """Return the inserted lengths (m) every step_m up to the last key step, key steps too."""
    last = key_steps_m[-1]
    dense = np.arange(1, int(np.floor(last / step_m + 1e-9)) + 1) * step_m
    lengths = np.unique(np.round(np.concatenate([dense, key_steps_m]), 12))
    return [float(v) for v in lengths if v > 0]


def playback(model, plan, target, step_m, constraints, iterations=50, progress=None,
             keep_off=None):
    """
    Return (dense Steps, flags) for a plan.

    :param model: the TentacleModel the plan was made with
    :param plan: a Plan (its directions are held; its key fields start the interpolation)
    :param target: callable (chain, inserted_m) -> (n + 1, 3) follow-the-leader target, m
    :param step_m: insertion between dense steps, m
    :param constraints: Constraints (field limits apply at every dense step; where the best
        field would change by more than max_field_change_t from the dense step before, the
        rig refuses it: a 3-axis field is fitted again within that change, a planar one
        held to it and flagged)
    :param iterations: Gauss-Newton budget per dense step
    :param progress: called with (steps done, steps, None) after every dense step
    :param keep_off: a KeepOff every dense step's field keeps the body off by (None: none)
    """
    key_m = np.array([s.inserted_m for s in plan.steps])
    key_fields = plan.fields_t
    steps, flags, start = [], [], None
    lengths = dense_lengths(list(key_m), step_m)
    for inserted_m in lengths:
        guess = np.array([np.interp(inserted_m, key_m, key_fields[:, axis]) for axis in range(3)])
        problem = Problem(model, [inserted_m], [target(model.chain(inserted_m), inserted_m)],
                          constraints, directions=plan.directions, start=start,
                          keep_off=keep_off)
        x = fit(problem, problem.pack(plan.directions, [guess]), iterations)
        change = constraints.max_field_change_t
        if change is not None and steps:   # the rig refuses a larger change: keep within
            previous, field = steps[-1].field_t, problem.unpack(x)[1][0]
            held = np.clip(field, previous - change, previous + change)
            if np.any(held != field) and problem.field_size == 3:
                # The best field the rig can reach from the step before: a fit within the
                # limits, as every field is (its contact, stability and convergence are
                # checked as any step's).
                problem.field_box_t = (previous - change, previous + change)
                x = fit(problem, problem.pack(plan.directions, [held]), iterations)
                held = np.clip(problem.unpack(x)[1][0], previous - change, previous + change)
                x = problem.pack(plan.directions, [held])
            elif np.any(held != field):   # a planar field: clipped, and said so
                x = problem.pack(plan.directions, [held])
                flags.append(f'field change held to the limit into the dense step at '
                             f'{inserted_m * 1e3:.1f} mm')
        solution = problem.simulate(x)[-1]
        step = problem.plan(x).steps[0]
        steps.append(step)
        if not step.converged:
            flags.append(f'dense step at {inserted_m * 1e3:.1f} mm did not converge')
        elif not step.stability > 0:
            flags.append(f'unstable dense step at {inserted_m * 1e3:.1f} mm')
        start = (solution.state, inserted_m)
        if progress is not None:
            progress(len(steps), len(lengths), None)
    return steps, flags
