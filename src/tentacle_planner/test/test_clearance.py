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
