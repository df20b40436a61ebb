#!/usr/bin/env python3
"""
Benchmark: every shipped scene planned as tentacle-plan plans it, with the figures to report.

For each config/scenes/*.yaml: the plan's full-shape RMS over the key steps (DESIGN.md's
shape error; mm and % of the tentacle length) in the planning model, the same plan re-checked
in the higher-fidelity model (4x sub-links, 3-DoF joints, magnet-to-magnet interaction) with
the difference, the worst perturbed model, the wall time of plan_scene (key steps, playback,
robustness and re-check), and the flags. For the chapter 3 scenes also the tip-driven
baseline and how far below it the shape-forming plan is (thesis Table 3.1: 48% for A).

Run: .venv/bin/python bench/plan_scenes.py
"""

import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]

from tentacle_model.statics import compile_kernels  # noqa: E402
from tentacle_planner.planner import plan_scene, shape_rms  # noqa: E402
from tentacle_planner.scene import load_scene  # noqa: E402


def main():
    """Plan every scene, print the table."""
    compile_kernels()
    print('  scene            planned (mm, % L)   re-checked (mm, change)   worst perturbed'
          '   time (s)  flags   tip-driven (mm, shape-forming below it)')
    for file in sorted((ROOT / 'config' / 'scenes').glob('*.yaml')):
        scene = load_scene(file)
        length = scene.tentacle.length_m
        t0 = time.perf_counter()
        result = plan_scene(scene)
        seconds = time.perf_counter() - t0
        planned = shape_rms(scene, result.plan.steps)
        rechecked = dict(result.verification)
        fidelity = next(v for k, v in rechecked.items() if k.startswith('higher fidelity'))
        worst = max(result.robustness, key=lambda row: row[2])
        baseline = ''
        if scene.name.startswith('ch3'):
            tip = shape_rms(scene, plan_scene(scene, tip_driven=True).plan.steps)
            baseline = f'{tip * 1e3:6.3f} mm, {100 * (1 - planned / tip):3.0f}% below'
        print(f'  {scene.name:15s}  {planned * 1e3:6.3f} mm {100 * planned / length:5.2f}%'
              f'   {fidelity * 1e3:6.3f} mm {(fidelity - planned) * 1e3:+7.3f} mm'
              f'   {worst[2] * 1e3:6.3f} mm ({worst[0]})  {seconds:7.1f}  {len(result.flags):5d}'
              f'   {baseline}')


if __name__ == '__main__':
    main()
