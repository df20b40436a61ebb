"""Discretisation: what is inserted, partial links, joint stiffness and loads."""

import numpy as np
import pytest
from tentacle_planner.chain import discretise


def test_uniform_rod_joint_stiffness_and_moments(cantilever):
    spec, length, ei, ma = cantilever
    chain = discretise(spec, sublinks=10)
    h = length / 10
    np.testing.assert_allclose(chain.lengths_m, h)
    assert chain.stiffness_n_m[0, 0] == pytest.approx(2 * ei / h)  # half cell at the clamp
    np.testing.assert_allclose(chain.stiffness_n_m[1:, 0], ei / h)
    np.testing.assert_allclose(chain.moments_a_m2[:, 0], ma * h)
    assert chain.masses_kg.sum() == pytest.approx(1400 * np.pi * 0.001 ** 2 * length)


def test_partial_insertion_keeps_the_distal_part(cantilever):
    spec, length, ei, _ = cantilever
    chain = discretise(spec, inserted_m=0.0075, sublinks=4)  # links of 5 mm: 2.5 mm + 5 mm
    np.testing.assert_allclose(chain.lengths_m, [0.0025, 0.005])
    np.testing.assert_allclose(chain.s_start_m, [0.0125, 0.015])
    assert chain.stiffness_n_m[0, 0] == pytest.approx(ei / 0.00125)
    assert discretise(spec, inserted_m=0.0, sublinks=4).size == 0


@pytest.mark.parametrize('kwargs, message', [
    ({'inserted_m': 0.03}, 'outside'), ({'inserted_m': -0.001}, 'outside'),
    ({'inserted_m': float('nan')}, 'outside'), ({'sublinks': 0}, 'sublinks'),
    ({'backbone_m': -1.0}, 'backbone')])
def test_bad_knobs_raise(cantilever, kwargs, message):
    with pytest.raises(ValueError, match=message):
        discretise(cantilever[0], **kwargs)
