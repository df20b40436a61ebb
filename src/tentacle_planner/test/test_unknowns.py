"""The plan's direction unknowns: directions and their derivatives, by finite differences."""

import numpy as np
import pytest
from tentacle_planner import unknowns


@pytest.mark.parametrize('angles', [1, 2])
def test_directions_and_their_derivatives(angles):
    rng = np.random.default_rng(angles)
    held = np.zeros((5, 3))
    held[1] = (0.0, 1.0, 0.0)                      # held, magnetised; 4: passive
    free = np.array([0, 2, 3])
    x = rng.uniform(-1.5, 1.5, 3 * angles + 6)     # the fields' unknowns after the angles
    directions, derivatives = unknowns.directions(x, held, free, angles)
    np.testing.assert_array_equal(directions[[1, 4]], held[[1, 4]])
    np.testing.assert_allclose(np.linalg.norm(directions[free], axis=1), 1.0, rtol=1e-15)
    azimuth = x[0:3 * angles:angles]
    elevation = x[1:3 * angles:2] if angles == 2 else np.zeros(3)
    np.testing.assert_allclose(np.arctan2(directions[free, 1], directions[free, 0]), azimuth,
                               atol=1e-12)
    np.testing.assert_allclose(np.arcsin(directions[free, 2]), elevation, atol=1e-12)
    eps = 1e-7
    for k, segment in enumerate(free):
        for j in range(angles):
            moved = x.copy()
            moved[k * angles + j] += eps
            fd = (unknowns.directions(moved, held, free, angles)[0] - directions) / eps
            np.testing.assert_allclose(derivatives[segment, j], fd[segment], atol=1e-6)
            assert not np.any(np.delete(fd, segment, axis=0))   # no other segment moves
    assert not np.any(derivatives[[1, 4]])
