#!/usr/bin/env python3
"""
Benchmark: every shipped scene planned as tentacle-plan plans it, with the figures to report.

For each config/scenes/*.yaml: the plan's full-shape RMS over the key steps (DESIGN.md's
shape error; mm and % of the tentacle length) in the planning model, the same plan re-checked
in the higher-fidelity model (4x sub-links, 3-DoF joints, magnet-to-magnet interaction) with
the difference, the worst perturbed model, the wall time of plan_scene (key steps, playback,
robustness and re-check), the least clearance to the scene's obstacles and walls over the
key and dense steps (negative: into one) with the steps that touch, and the flags. For the
chapter 3 scenes also the tip-driven baseline, planned and re-checked, and how far below it
the shape-forming plan is (thesis Table 3.1: 48% for A).

Run: .venv/bin/python bench/plan_scenes.py
"""

import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]

from tentacle_model.statics import compile_kernels  # noqa: E402
from tentacle_planner.planner import plan_scene, shape_rms, step_clearance  # noqa: E402
from tentacle_planner.scene import load_scene  # noqa: E402


def main():
    """Plan every scene, print the table."""
    compile_kernels()
    print('  scene            planned (mm, % L)   re-checked (mm, change)   worst perturbed'
          '   time (s)  clearance (mm, steps touching)  flags   tip-driven planned / '
          're-checked (mm, shape-forming below it)')
    for file in sorted((ROOT / 'config' / 'scenes').glob('*.yaml')):
        scene = load_scene(file)
        length = scene.tentacle.length_m
        t0 = time.perf_counter()
        result = plan_scene(scene)
        seconds = time.perf_counter() - t0
        planned = shape_rms(scene, result.plan.steps)
        fidelity = higher_fidelity(result)
        worst = max(result.robustness, key=lambda row: row[2])
        gaps = [step_clearance(scene, s)[0] for s in result.plan.steps + result.playback_steps]
        clear = (f'{min(gaps) * 1e3:6.3f} mm, {sum(g <= 0 for g in gaps):3d}'
                 if scene.obstacles or scene.walls else '      (none)')
        baseline = ''
        if scene.name.startswith('ch3'):
            tip = plan_scene(scene, tip_driven=True)
            tip_planned, tip_checked = shape_rms(scene, tip.plan.steps), higher_fidelity(tip)
            baseline = (f'{tip_planned * 1e3:6.3f} / {tip_checked * 1e3:6.3f} mm, '
                        f'{100 * (1 - planned / tip_planned):3.0f}% / '
                        f'{100 * (1 - fidelity / tip_checked):3.0f}% below')
        print(f'  {scene.name:15s}  {planned * 1e3:6.3f} mm {100 * planned / length:5.2f}%'
              f'   {fidelity * 1e3:6.3f} mm {(fidelity - planned) * 1e3:+7.3f} mm'
              f'   {worst[2] * 1e3:6.3f} mm ({worst[0]})  {seconds:7.1f}  {clear:>20s}'
              f'  {len(result.flags):5d}   {baseline}', flush=True)


def higher_fidelity(result):
    """Return a SceneResult's shape RMS re-checked in the higher-fidelity model, m."""
    return next(v for k, v in result.verification if k.startswith('higher fidelity'))


if __name__ == '__main__':
    main()
