"""
The shipped scenes plan as the README reports, and so do scenes nobody tuned for.

Issue 8 section 6: every shipped scene within 5% of the tentacle length (full-shape RMS,
DESIGN.md's definition) in the planning model, re-checked in a higher-fidelity one. Issue 18:
judged in the re-check, scene A at least 48% below the tip-driven baseline (thesis Table
3.1) and scenes B, C and D no worse than it.
"""

from dataclasses import replace
import math
import pathlib

import numpy as np
import pytest
from tentacle_planner.planner import plan_scene, shape_rms, step_clearance
from tentacle_planner.scene import load_scene, parse_scene

ROOT = pathlib.Path(__file__).resolve().parents[3]
SCENES = sorted((ROOT / 'config' / 'scenes').glob('*.yaml'))


PLANNED = {}   # scene name -> (scene, SceneResult): each shipped scene planned once


def planned_scene(name):
    """Return (scene, SceneResult) of a shipped scene, planned with the defaults."""
    if name not in PLANNED:
        scene = load_scene(ROOT / 'config' / 'scenes' / f'{name}.yaml')
        PLANNED[name] = scene, plan_scene(scene)
    return PLANNED[name]


@pytest.fixture(scope='module', params=[p.stem for p in SCENES])
def planned(request):
    return planned_scene(request.param)


def test_every_shipped_scene_plans_within_5_percent(planned):
    scene, result = planned
    length = scene.tentacle.length_m
    assert result.flags == []
    assert shape_rms(scene, result.plan.steps) <= 0.05 * length
    rechecked = dict(result.verification)
    assert any(what.startswith('higher fidelity') for what in rechecked)
    assert all(rms <= 0.05 * length for rms in rechecked.values())


def higher_fidelity(result):
    """Return a SceneResult's shape RMS re-checked in the higher-fidelity model, m."""
    return next(rms for what, rms in result.verification if what.startswith('higher fidelity'))


@pytest.mark.parametrize('name', ['ch3_a', 'ch3_b', 'ch3_c', 'ch3_d'])
def test_chapter_3_plans_beat_the_tip_driven_baseline_as_the_rig_would_show(name):
    # Issue 18: judged in the higher-fidelity re-check, not the planning model: at most the
    # baseline's error on B, C and D, at least 48% below it on A (thesis Table 3.1).
    scene, shaped = planned_scene(name)
    tip_driven = plan_scene(scene, tip_driven=True)
    assert np.allclose([np.linalg.norm(d) for d in tip_driven.plan.directions], 1.0)
    assert np.allclose(tip_driven.plan.directions[:, 1:], 0.0)   # every segment axial
    below = 0.48 if name == 'ch3_a' else 0.0
    assert higher_fidelity(shaped) <= (1 - below) * higher_fidelity(tip_driven)


def channel_walls(points_m, width_m):
    """Return Walls of an open channel width_m wide along a planar path (make_duct_walls.py)."""
    import importlib.util
    from tentacle_planner.scene import Wall
    spec = importlib.util.spec_from_file_location(
        'make_duct_walls', ROOT / 'config' / 'scenes' / 'make_duct_walls.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return tuple(Wall(points) for points in module.walls(points_m, width_m))


def chapter3_scene(headings_deg, name, obstacles=()):
    """
    Return a chapter 3 scene on a path of four 14 mm straight headings, deg, with obstacles.

    :param obstacles: [(centre (3,) m, radius m)]
    """
    points, here = [np.zeros(3)], np.zeros(3)
    for h in np.radians(np.append(headings_deg, headings_deg[-1])):
        step = np.array([math.sin(h), -math.cos(h), 0.0]) * 0.0005
        for _ in range(28 if len(points) < 113 else 4):
            here = here + step
            points.append(here)
    document = {'tentacle': '../tentacles/tentacle_chapter3.yaml',
                'path': {'points_m': np.round(points, 9).tolist()},
                'insertion_steps_m': [0.014, 0.028, 0.042, 0.056],
                'coil': {'max_field_t': 0.02},
                'model': {'dof': 1, 'gravity_m_s2': [0.0, -9.81, 0.0]},
                'magnetisation': {'planar': True},
                'obstacles': [{'centre_m': list(c), 'radius_m': r} for c, r in obstacles]}
    return parse_scene(document, ROOT / 'config' / 'scenes' / f'{name}.yaml')


def untuned_scene(seed):
    """
    Return a chapter 3 scene on a random four-segment path (turns up to 12 deg a joint).

    In a channel 3.5 mm wide (0.75 mm each side of the 2 mm body), as the pancreatic duct's.
    """
    headings = np.cumsum(np.random.default_rng(seed).uniform(-12.0, 12.0, 4))
    scene = chapter3_scene(headings, f'untuned_{seed}')
    return replace(scene, walls=channel_walls(scene.path.points_m, 3.5e-3))


@pytest.mark.parametrize('seed', [11, 12, 13])
def test_scenes_nobody_tuned_for_plan_the_same_way_clear_of_their_walls(seed):
    scene = untuned_scene(seed)
    result = plan_scene(scene)
    assert result.flags == []      # a step touching a wall would be flagged
    assert shape_rms(scene, result.plan.steps) <= 0.05 * scene.tentacle.length_m
    gaps = [step_clearance(scene, step)[0] for step in result.plan.steps]
    assert min(gaps) >= 0.9 * scene.clearance_margin_m   # the margin kept (penalty: nearly)


def test_an_obstacle_beside_the_path_the_unaware_plan_runs_into_is_kept_off():
    # Issue 18 part 1: an S-shaped path, a ball 0.75 mm off the path's body on the side the
    # plan that ignores obstacles strays to (about 1 mm, at 42 mm inserted).
    headings, off_m, ball_m = [20, 45, 15, -20], 0.00075, 0.002
    open_scene = chapter3_scene(headings, 's_shaped')
    unaware = plan_scene(open_scene).plan
    path = open_scene.path.points_m
    stray, where = max(((np.min(np.linalg.norm(path - p, axis=1)), p)
                        for s in unaware.steps for p in s.points_m[1:]), key=lambda d: d[0])
    assert stray > off_m
    nearest = path[np.argmin(np.linalg.norm(path - where, axis=1))]
    side = (where - nearest) / np.linalg.norm(where - nearest)
    body_m = open_scene.tentacle.segments[0].radius_m
    scene = chapter3_scene(headings, 's_shaped',
                           [(nearest + side * (body_m + off_m + ball_m), ball_m)])
    assert min(step_clearance(scene, s)[0] for s in unaware.steps) < 0   # it runs into it
    aware = plan_scene(scene)
    assert aware.flags == []
    assert min(step_clearance(scene, s)[0] for s in aware.plan.steps) >= \
        0.9 * scene.clearance_margin_m
    assert shape_rms(scene, aware.plan.steps) <= 0.05 * scene.tentacle.length_m


def test_refinements_double_the_sub_links_up_to_the_re_check():
    from tentacle_planner.planner import refinements
    assert refinements(1, 4) == [2, 4]
    assert refinements(1, 3) == [2, 3]
    assert refinements(2, 4) == [4]
    assert refinements(4, 4) == []


def test_refined_plans_come_best_first_and_asked_again_every_one_in_order():
    # The first refined plan is the best of those refined until one is clean; asked again
    # (its dense playback touched a wall), every plan is refined and the rest come in rank
    # order (bile_duct once took a 3.7 mm plan here before a 0.47 mm one not yet refined).
    from tentacle_planner.optimise import clean, leading
    from tentacle_planner.planner import problem_of, refined
    scene = load_scene(ROOT / 'config' / 'scenes' / 'ch3_b.yaml')
    problem = problem_of(scene)
    found = leading(problem, keep=4, seed=0, starts=4, iterations=30)
    ranks = []
    for finer, plan, checked in refined(scene, problem, found, 30, workers=1):
        ranks.append(finer.rank(plan, checked[0][-1][1], flags=len(checked[1])))
    assert len(ranks) == len(found)
    assert clean(ranks[0]) and ranks[0] == min(ranks[:2])   # the first batch's best
    assert ranks[1:] == sorted(ranks[1:])
