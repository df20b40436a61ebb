"""Clearance of a body from obstacles and walls, against distances worked by hand."""

import numpy as np
import pytest
from tentacle_planner.clearance import clearance
from tentacle_planner.scene import Sphere, Wall

BODY = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.0, 0.0]])  # straight along x
RADII = [0.001, 0.0005]


def test_a_sphere_beside_a_link_and_past_the_tip():
    beside = Sphere(np.array([0.005, 0.004, 0.0]), 0.002)   # 4 mm off link 1's axis
    past = Sphere(np.array([0.0215, 0.0, 0.0]), 0.0008)     # 1.5 mm beyond the tip
    assert clearance(BODY, RADII, [beside]) == pytest.approx((0.004 - 0.001 - 0.002,
                                                              'obstacle 1'))
    assert clearance(BODY, RADII, [beside, past]) == pytest.approx((0.0015 - 0.0005 - 0.0008,
                                                                    'obstacle 2'))


def test_overlap_is_negative_and_walls_are_points():
    inside = Sphere(np.array([0.015, 0.001, 0.0]), 0.001)   # its surface crosses link 2
    wall = Wall(np.array([[0.012, 0.0, 0.003], [0.0, -0.01, 0.0]]))
    gap, what = clearance(BODY, RADII, [inside], [wall])
    assert (gap, what) == pytest.approx((0.001 - 0.0005 - 0.001, 'obstacle 1'))
    assert clearance(BODY, RADII, walls=[wall]) == pytest.approx((0.003 - 0.0005, 'wall 1'))
    assert clearance(BODY, RADII) == (float('inf'), None)


def test_the_gaps_gradients_agree_with_finite_differences():
    rng = np.random.default_rng(7)
    from tentacle_planner.clearance import link_gap_gradients, link_gaps
    for _ in range(20):
        body = np.cumsum(rng.normal(0.0, 0.004, (6, 3)), axis=0)
        radii = rng.uniform(0.0003, 0.001, 5)
        spheres = [Sphere(rng.normal(0.0, 0.01, 3), 0.001) for _ in range(2)]
        walls = [Wall(rng.normal(0.0, 0.01, (30, 3)))]
        gaps, gradients = link_gap_gradients(body, radii, spheres, walls)
        assert gaps == pytest.approx(link_gaps(body, radii, spheres, walls), abs=1e-15)
        step = 1e-8
        for joint in range(len(body)):
            for axis in range(3):
                ahead, behind = body.copy(), body.copy()
                ahead[joint, axis] += step
                behind[joint, axis] -= step
                numeric = (link_gaps(ahead, radii, spheres, walls)
                           - link_gaps(behind, radii, spheres, walls)) / (2 * step)
                analytic = np.zeros_like(gaps)
                if joint < len(radii):            # the start of link `joint`
                    analytic[joint] += gradients[joint, :, 0, axis]
                if joint > 0:                     # the end of link `joint - 1`
                    analytic[joint - 1] += gradients[joint - 1, :, 1, axis]
                assert numeric == pytest.approx(analytic, abs=1e-6), (joint, axis)


def test_the_gradient_points_away_from_the_obstacle_and_splits_along_the_link():
    from tentacle_planner.clearance import link_gap_gradients
    beside = Sphere(np.array([0.0025, 0.004, 0.0]), 0.002)   # a quarter along link 1
    gaps, gradients = link_gap_gradients(BODY, RADII, [beside])
    assert gaps[0, 0] == pytest.approx(0.004 - 0.001 - 0.002)
    assert gradients[0, 0] == pytest.approx(np.array([[0.0, -0.75, 0.0], [0.0, -0.25, 0.0]]))
