"""The simulated rig's physics against independent references: the elastica, geometry."""

import dataclasses
import math
import pathlib

import numpy as np
import pytest
from tentacle_model.elastica import cantilever_tip
from tentacle_planner.planner import plan_scene
from tentacle_planner.scene import load_scene
from tentacle_planner.schedule_file import read_schedule
from tentacle_planner.schedule_writer import write_schedule_file
from tentacle_sim.world import made_to_plan, World
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]

FIELD_T = 5e-3
ACTUATION = np.diag([1e-3, 1e-3, 1e-3])   # 1 mT per A on each axis
CURRENTS_A = [0.0, FIELD_T / 1e-3, 0.0]   # 5 mT along y: 90 deg to the rod


def settle(world, currents_a, inserter_m, steps=200):
    """Step until the body converges (warm-started, a budget per step); return it."""
    for _ in range(steps):
        body = world.step(currents_a, inserter_m)
        if body.converged:
            return body
    raise AssertionError(f'no convergence in {steps} steps: {body.reason}')


def elastica(c, inserted_m, stiffness=1.0):
    """Return the elastica's tip (x, y) for the cantilever c in FIELD_T at 90 deg."""
    return cantilever_tip(inserted_m, stiffness * c.EI_N_M2, c.MA_A_M, FIELD_T, 90.0)


@pytest.mark.parametrize('fraction', [1.0, 0.75])
def test_the_body_agrees_with_the_elastica_within_2_percent(cantilever, fraction):
    inserted_m = fraction * cantilever.LENGTH_M
    world = World(cantilever.scene(), ACTUATION, time_budget_s=0.005)
    body = settle(world, CURRENTS_A, inserted_m)
    assert body.inserted_m == pytest.approx(inserted_m)
    off = np.linalg.norm(body.points_m[-1, :2] - elastica(cantilever, inserted_m))
    assert off < 0.02 * inserted_m
    assert body.field_t == pytest.approx(np.array([0.0, FIELD_T, 0.0]))


def test_a_stiffness_factor_acts_as_a_softer_rod(cantilever):
    c = cantilever
    scene = cantilever.scene(mismatch={'stiffness_factor': 0.8})
    body = settle(World(scene, ACTUATION), CURRENTS_A, c.LENGTH_M)
    softer, nominal = elastica(c, c.LENGTH_M, 0.8), elastica(c, c.LENGTH_M)
    off = np.linalg.norm(body.points_m[-1, :2] - softer)
    assert off < 0.02 * c.LENGTH_M
    # and the mismatch is what moved it: it lies far nearer the softer rod than the nominal
    assert off < 0.25 * np.linalg.norm(softer - nominal)


def test_a_coil_factor_scales_that_coils_field(cantilever):
    scene = cantilever.scene(mismatch={'actuation_matrix_factor': [1.0, 0.9, 1.0]})
    world = World(scene, ACTUATION)
    assert world.field_t([1.0, 2.0, 3.0]) == pytest.approx(np.array([1e-3, 1.8e-3, 3e-3]))


def test_an_insertion_offset_and_angle_move_the_base(cantilever):
    c = cantilever
    scene = cantilever.scene(mismatch={'insertion_offset_m': [0.0, 5e-4, 0.0],
                                       'insertion_angle_deg': 10.0})
    body = World(scene, ACTUATION).step([0.0, 0.0, 0.0], c.LENGTH_M)   # no field: straight
    assert body.points_m[0] == pytest.approx(np.array([0.0, 5e-4, 0.0]))
    tip = body.points_m[-1] - body.points_m[0]
    assert math.degrees(math.atan2(tip[1], tip[0])) == pytest.approx(10.0)


def test_the_stage_position_is_the_inserted_length_past_the_offset(cantilever):
    c = cantilever
    world = World(cantilever.scene(), ACTUATION, insertion_offset_m=0.002)
    assert world.step([0, 0, 0], 0.012).inserted_m == pytest.approx(0.010)
    assert world.step([0, 0, 0], 0.001).inserted_m == 0.0     # behind the insertion point
    assert world.step([0, 0, 0], 0.5).inserted_m == pytest.approx(c.LENGTH_M)  # all of it


def test_contact_with_an_obstacle_is_counted_with_its_depth(cantilever):
    c = cantilever
    # A straight rod along x past a ball at (10, 1.5) mm of radius 1 mm: the surfaces overlap
    # by 1 + 1 - 1.5 = 0.5 mm; a link is in contact where its axis passes within 2 mm.
    centre, radius = np.array([0.010, 0.0015, 0.0]), 0.001
    scene = cantilever.scene(obstacles=[{'centre_m': centre.tolist(), 'radius_m': radius}])
    body = World(scene, ACTUATION).step([0, 0, 0], c.LENGTH_M)
    assert body.contact_depth_m == pytest.approx(c.RADIUS_M + radius - 0.0015)
    edges = np.linspace(0.0, c.LENGTH_M, 33)   # the 32 links' ends
    nearest_dx = np.maximum(0.0, np.maximum(edges[:-1] - centre[0], centre[0] - edges[1:]))
    expected = np.count_nonzero(np.hypot(nearest_dx, 0.0015) < c.RADIUS_M + radius)
    assert body.contacts == expected > 0
    clear = World(cantilever.scene(obstacles=[{'centre_m': [0.010, 0.005, 0.0],
                                               'radius_m': radius}]), ACTUATION)
    assert clear.step([0, 0, 0], c.LENGTH_M).contacts == 0


def test_the_camera_sees_the_in_plane_width_and_one_stretch_of_magnets():
    root = pathlib.Path(__file__).resolve().parents[3] / 'config' / 'scenes'
    duct = World(load_scene(root / 'pancreatic_duct.yaml'), ACTUATION)
    assert duct.body_width_m() == pytest.approx(0.002)               # a 2 mm rod
    assert duct.magnet_ranges_m(0.03) == [pytest.approx((0.0, 0.03))]   # five segments, one
    ribbon = World(load_scene(root / 'ch6_coiling.yaml'), ACTUATION)
    assert ribbon.body_width_m() == pytest.approx(0.002)   # 2 mm wide in the plane, 10 tall


def test_a_plan_made_finer_than_the_scene_is_simulated_in_its_sub_links(tmp_path):
    scene = load_scene(ROOT / 'config' / 'scenes' / 'pancreatic_duct.yaml')
    short = dataclasses.replace(scene, insertion_steps_m=(0.01,), playback_step_m=None)
    file = write_schedule_file(tmp_path, plan_scene(short, starts=1, iterations=10))
    document = yaml.safe_load(file.read_text())
    document['model']['sublinks'] = 2   # as if the planner had polished it in 2 sub-links
    file.write_text(yaml.safe_dump(document))
    schedule = read_schedule(file)
    made = made_to_plan(scene, schedule)
    assert made.model.sublinks == 2 and scene.model.sublinks == 1
    assert made.model.dof == scene.model.dof and made.walls == scene.walls
    planned = [s.magnetisation_a_per_m for s in schedule.tentacle_spec().segments]
    assert np.array_equal([s.magnetisation_a_per_m for s in made.tentacle.segments], planned)
    body = World(made, ACTUATION).step(np.zeros(3), 0.01)
    assert len(body.points_m) == 3   # the 10 mm segment in, as 2 sub-links: 3 points
    assert len(World(scene, ACTUATION).step(np.zeros(3), 0.01).points_m) == 2
