"""
The shipped scenes plan as the README reports, and so do scenes nobody tuned for.

Issue 8 section 6: every shipped scene within 5% of the tentacle length (full-shape RMS,
DESIGN.md's definition) in the planning model, re-checked in a higher-fidelity one; scene A
at least 48% below the tip-driven baseline (thesis Table 3.1).
"""

import math
import pathlib

import numpy as np
import pytest
from tentacle_planner.planner import plan_scene, shape_rms
from tentacle_planner.scene import load_scene, parse_scene

ROOT = pathlib.Path(__file__).resolve().parents[3]
SCENES = sorted((ROOT / 'config' / 'scenes').glob('*.yaml'))


@pytest.fixture(scope='module', params=[p.stem for p in SCENES])
def planned(request):
    scene = load_scene(ROOT / 'config' / 'scenes' / f'{request.param}.yaml')
    return scene, plan_scene(scene)


def test_every_shipped_scene_plans_within_5_percent(planned):
    scene, result = planned
    length = scene.tentacle.length_m
    assert result.flags == []
    assert shape_rms(scene, result.plan.steps) <= 0.05 * length
    rechecked = dict(result.verification)
    assert any(what.startswith('higher fidelity') for what in rechecked)
    assert all(rms <= 0.05 * length for rms in rechecked.values())


def test_scene_a_is_48_percent_below_the_tip_driven_baseline():
    scene = load_scene(ROOT / 'config' / 'scenes' / 'ch3_a.yaml')
    shaped = shape_rms(scene, plan_scene(scene).plan.steps)
    tip_driven = plan_scene(scene, tip_driven=True)
    assert np.allclose([np.linalg.norm(d) for d in tip_driven.plan.directions], 1.0)
    assert np.allclose(tip_driven.plan.directions[:, 1:], 0.0)   # every segment axial
    assert shaped <= (1 - 0.48) * shape_rms(scene, tip_driven.plan.steps)


def untuned_scene(seed):
    """Return a chapter 3 scene on a random four-segment path (turns up to 12 deg a joint)."""
    rng = np.random.default_rng(seed)
    headings = np.cumsum(rng.uniform(-12.0, 12.0, 4))
    points, here = [np.zeros(3)], np.zeros(3)
    for h in np.radians(np.append(headings, headings[-1])):
        step = np.array([math.sin(h), -math.cos(h), 0.0]) * 0.0005
        for _ in range(28 if len(points) < 113 else 4):
            here = here + step
            points.append(here)
    document = {'tentacle': '../tentacles/tentacle_chapter3.yaml',
                'path': {'points_m': np.round(points, 9).tolist()},
                'insertion_steps_m': [0.014, 0.028, 0.042, 0.056],
                'coil': {'max_field_t': 0.02},
                'model': {'dof': 1, 'gravity_m_s2': [0.0, -9.81, 0.0]},
                'magnetisation': {'planar': True}}
    return parse_scene(document, ROOT / 'config' / 'scenes' / f'untuned_{seed}.yaml')


@pytest.mark.parametrize('seed', [11, 12, 13])
def test_scenes_nobody_tuned_for_plan_the_same_way(seed):
    scene = untuned_scene(seed)
    result = plan_scene(scene)
    assert result.flags == []
    assert shape_rms(scene, result.plan.steps) <= 0.05 * scene.tentacle.length_m
