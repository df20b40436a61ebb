"""Frames and offsets: the conversions DESIGN.md "Frames" defines, and their round trips."""

import numpy as np
import pytest
from tentacle_common import frames


def test_workspace_is_coils_xy_from_the_insertion_point():
    points = np.array([[0.01, -0.02, 0.003], [0.0, 0.0, 0.0]])
    assert frames.workspace_from_coils(points) == pytest.approx(points[:, :2])
    base = (0.001, 0.002, 0.004)
    xy = frames.workspace_from_coils(points, base)
    assert xy == pytest.approx(np.array([[0.009, -0.022], [-0.001, -0.002]]))
    back = frames.coils_from_workspace(xy, base)
    assert back[:, :2] == pytest.approx(points[:, :2]) and np.all(back[:, 2] == 0.004)


def test_inserted_length_and_stage_position_are_inverse():
    assert frames.inserted_length_m(0.012, 0.002) == pytest.approx(0.010)
    assert frames.stage_position_m(0.010, 0.002) == pytest.approx(0.012)
    assert frames.inserted_length_m(0.001, 0.002) == 0.0   # behind the insertion point
