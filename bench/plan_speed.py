#!/usr/bin/env python3
"""
Benchmark: wall time to plan a scene against the plan's quality, over the optimiser's settings.

For config/scenes/pancreatic_duct.yaml (the braided 5-link 3-DoF tentacle, five key steps)
it plans with 1 to 8 starts of the multi-start and 25 to 100 model evaluations per start,
with each objective: the forward model's equilibrium ("equilibrium"), the thesis' torque
balance at the target shape alone ("torque balance", then verified), and the torque balance
as a first stage before the equilibrium ("staged"). Per setting it prints the median wall
time of the key-step plan (verified in the forward model; the dense 1 mm playback timed on
its own) against the shape error (RMS over the key steps, DESIGN.md's definition, % of L),
with the tip-driven baseline beside it. Target: the key-step plan in at most 1 s, as good as
the best found (within 10%). Writes bench/out/plan_speed.png (time against error).

Then tentacle-plan's own settings, as a lab runs it (plan_scene: the search on two cores,
the polish in the model the scene needs, the re-check and the robustness report; the dense
playback left out, timed above): the default (two rounds of two starts, 50 evaluations
each), one round (2 starts), and the exhaustive search of before (8 starts x 100), over
seeds 0-9, with the median time, the shape error planned and re-checked, the clearance and
the flags; against the 1 s target and the exhaustive search's re-checked error. Last,
one evaluation of the objective with its Jacobian, the compiled key steps against the
generic per-step path, side by side.

Run: .venv/bin/python bench/plan_speed.py [--quick]
"""

import argparse
from dataclasses import replace
import pathlib
import statistics
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
SOURCES = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]
sys.path[:0] = SOURCES

from tentacle_model.statics import compile_kernels  # noqa: E402
from tentacle_planner import paths  # noqa: E402
from tentacle_planner.balance import BalanceProblem  # noqa: E402
from tentacle_planner.optimise import optimise  # noqa: E402
from tentacle_planner.planner import (plan_scene, problem_of, shape_rms,  # noqa: E402
                                      step_clearance)
from tentacle_planner.playback import playback  # noqa: E402
from tentacle_planner.scene import load_scene  # noqa: E402

SCENE = ROOT / 'config' / 'scenes' / 'pancreatic_duct.yaml'
TARGET_S = 1.0
OBJECTIVES = ('equilibrium', 'staged', 'torque balance')


def timed(scene, repeats, objective, **options):
    """Return (median seconds, plan) of planning the key steps with an objective."""
    times = []
    for _ in range(repeats):
        problem = problem_of(scene, options.get('tip_driven', False))
        t0 = time.perf_counter()
        plan = optimise(BalanceProblem(problem) if objective == 'torque balance' else problem,
                        seed=0, starts=options['starts'], iterations=options['iterations'],
                        first_stage=objective == 'staged')
        times.append(time.perf_counter() - t0)
    return statistics.median(times), plan


def main():
    """Measure, print the table, write the plot."""
    parser = argparse.ArgumentParser(description=__doc__.strip().split('\n')[0])
    parser.add_argument('--quick', action='store_true', help='fewer settings and repeats')
    opts = parser.parse_args()
    compile_kernels()
    scene = load_scene(SCENE)
    length = scene.tentacle.length_m
    repeats = 1 if opts.quick else 3
    settings = [(1, 25), (1, 50), (1, 100), (2, 100), (4, 100), (8, 100)]
    if opts.quick:
        settings = [(1, 25), (2, 100)]
    rows = []
    print(f'{scene.name}: {len(scene.insertion_steps_m)} key steps, '
          f'{scene.tentacle_model().chain(length).size} links, 3-DoF; median of {repeats}')
    print('  plan           objective       starts  evaluations/start  time (s)  '
          'shape RMS (% of L)  flags')
    for tip_driven, objective in [(False, o) for o in OBJECTIVES] + [(True, 'equilibrium')]:
        for starts, iterations in settings:
            seconds, plan = timed(scene, repeats, objective, starts=starts,
                                  iterations=iterations, tip_driven=tip_driven)
            error = shape_rms(scene, plan.steps) / length
            rows.append((tip_driven, starts, iterations, seconds, error, objective))
            name = 'tip-driven' if tip_driven else 'shape-forming'
            print(f'  {name:13s}  {objective:14s}  {starts:6d}  {iterations:17d}  '
                  f'{seconds:8.3f}  {100 * error:18.2f}  {len(plan.flags)}')
    problem = problem_of(scene)
    plan = optimise(problem, seed=0, starts=1, iterations=100)
    t0 = time.perf_counter()
    dense, flags = playback(problem.model, plan, lambda chain, inserted: paths.targets(
        scene.path, chain, inserted), scene.playback_step_m, problem.constraints)
    dense_s = time.perf_counter() - t0
    print(f'  dense playback: {len(dense)} steps of {scene.playback_step_m * 1e3:g} mm in '
          f'{dense_s:.2f} s ({1e3 * dense_s / len(dense):.1f} ms a step), {len(flags)} flags')
    # The target: a plan as good as the best one found (within 10% of its error, and within
    # 5% of L, the results target) in at most TARGET_S.
    shaped = [r for r in rows if not r[0]]
    for objective in OBJECTIVES:
        mine = [r for r in shaped if r[5] == objective]
        quick = min(mine, key=lambda r: r[3])
        lowest = min(r[4] for r in mine)
        print(f'  {objective}: best {100 * lowest:.2f}% of L; fastest '
              f'{quick[3]:.3f} s at {100 * quick[4]:.2f}%')
    good = min(r[4] for r in shaped)
    fast = [r for r in shaped if r[3] <= TARGET_S and r[4] <= max(1.1 * good, 0) and
            r[4] <= 0.05]
    baseline = min(r[4] for r in rows if r[0])
    if fast:
        best = min(fast, key=lambda r: r[3])
        print(f'  target: {best[3]:.3f} s (<= {TARGET_S:g} s) with {best[1]} start(s) x '
              f'{best[2]} evaluations ({best[5]}), shape RMS {100 * best[4]:.2f}% of L '
              f'(best found {100 * good:.2f}%, tip-driven {100 * baseline:.2f}%): met')
    else:
        print(f'  target: no setting reaches the best error ({100 * good:.2f}% of L) within '
              f'{TARGET_S:g} s: NOT MET')
    lab_settings(scene, 10)
    evaluation_cost()
    out = ROOT / 'bench' / 'out'
    out.mkdir(exist_ok=True)
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for (tip_driven, objective), marker in zip(
            [(False, o) for o in OBJECTIVES] + [(True, 'equilibrium')], 'o^vs'):
        chosen = [r for r in rows if r[0] == tip_driven and r[5] == objective]
        ax.plot([r[3] for r in chosen], [100 * r[4] for r in chosen], marker + '-',
                label='tip-driven baseline' if tip_driven else f'shape-forming, {objective}')
        for r in chosen:
            ax.annotate(f'{r[1]}x{r[2]}', (r[3], 100 * r[4]), fontsize=7)
    ax.axvline(TARGET_S, color='0.6', ls=':')
    ax.set_xscale('log')
    ax.set_xlabel('plan time (s), key steps, verified')
    ax.set_ylabel('shape RMS over the key steps (% of L)')
    ax.set_title(f'{scene.name}: plan time against plan quality (starts x evaluations)',
                 fontsize=9)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / 'plan_speed.png', dpi=110)
    print(f'  wrote {out / "plan_speed.png"}')


LAB_SETTINGS = (('default: 4 starts x 50 evaluations', {}),
                ('one round: 2 starts x 50', {'starts': 2, 'min_gain': None}),
                ('exhaustive: 8 starts x 100', {'starts': 8, 'iterations': 100,
                                                'min_gain': None}))


def lab_settings(scene, seeds):
    """Print plan_scene's time and errors for tentacle-plan's settings, medians over seeds."""
    length = scene.tentacle.length_m
    keys_only = replace(scene, playback_step_m=None)
    print(f'  tentacle-plan settings (plan_scene without the dense playback; seeds 0-'
          f'{seeds - 1}, medians): time (s), planned / re-checked shape RMS (% of L), '
          'least clearance (mm), flags')
    rows = []
    for name, options in LAB_SETTINGS:
        runs = []
        for seed in range(seeds):
            t0 = time.perf_counter()
            result = plan_scene(keys_only, seed=seed, **options)
            seconds = time.perf_counter() - t0
            rechecked = next(rms for what, rms in result.verification
                             if what.startswith('higher fidelity'))
            runs.append((seconds, shape_rms(scene, result.plan.steps) / length,
                         rechecked / length,
                         min(step_clearance(scene, s)[0] for s in result.plan.steps),
                         len(result.flags)))
        median = [statistics.median(column) for column in zip(*runs)]
        rows.append((name, median, runs))
        print(f'    {name:40s} {median[0]:6.2f} s  {100 * median[1]:5.2f} / '
              f'{100 * median[2]:5.2f}%  {1e3 * median[3]:6.3f} mm  {max(r[4] for r in runs)}'
              f'   (re-checked per seed: '
              + ', '.join(f'{100 * r[2]:.2f}%' for r in runs) + ')', flush=True)
    # The best plan unlimited settings find is the exhaustive search's, seed by seed: the
    # least of all its runs is seed luck, which the exhaustive median itself misses by 11%.
    (_, default, default_runs), (_, exhaustive, exhaustive_runs) = rows[0], rows[-1]
    paired = statistics.median(d[2] / e[2] for d, e in zip(default_runs, exhaustive_runs))
    best = min(r[2] for _, _, runs in rows for r in runs)
    met = default[0] <= TARGET_S and default[2] <= 1.1 * exhaustive[2]
    print(f'  target: the default in {default[0]:.2f} s (<= {TARGET_S:g} s) re-checked at '
          f'{100 * default[2]:.2f}% of L, within 10% of the exhaustive search at '
          f'{100 * exhaustive[2]:.2f}% (per seed a median {paired:.2f} x it; the least of any '
          f'run {100 * best:.2f}%): ' + ('met' if met else 'NOT MET'))


def evaluation_cost(repeats=300):
    """Print one objective evaluation's time, compiled key steps against the generic path."""
    print('  one evaluation (residuals and Jacobian, all key steps), side by side:')
    for name in ('pancreatic_duct', 'ch3_b'):
        scene = load_scene(ROOT / 'config' / 'scenes' / f'{name}.yaml')
        problem = problem_of(scene)
        plan = optimise(problem, seed=0, starts=1, iterations=25)
        x = problem.pack(plan.directions, plan.fields_t)
        times = {}
        compiled = problem._steps
        for path, steps in (('compiled', compiled), ('generic', None)):
            problem._steps = steps   # None: the per-step Python path (models with dipoles)
            problem.residuals(x)
            t0 = time.perf_counter()
            for _ in range(repeats):
                problem.residuals(x)
            times[path] = (time.perf_counter() - t0) / repeats
        problem._steps = compiled
        print(f'    {name:16s} ({scene.model.dof}-DoF model, {len(scene.insertion_steps_m)} '
              f'key steps): compiled {1e6 * times["compiled"]:6.0f} us, generic '
              f'{1e6 * times["generic"]:6.0f} us ({times["generic"] / times["compiled"]:.1f}x)')


if __name__ == '__main__':
    main()
