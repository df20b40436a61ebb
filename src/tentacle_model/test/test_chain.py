"""Discretisation: what is inserted, partial links, joint stiffness and loads."""

import numpy as np
import pytest
from tentacle_model.chain import discretise


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
    ({'backbone_m': -1.0}, 'backbone'), ({'sublinks': float('inf')}, 'sublinks'),
    ({'backbone_m': 0.01}, "tentacle 'cantilever' has no backbone"),
    ({'sublinks': 100_001}, 'more than the 100000 any joint model solves')])
def test_bad_knobs_raise(cantilever, kwargs, message):
    with pytest.raises(ValueError, match=message):
        discretise(cantilever[0], **kwargs)


def test_links_know_their_segment_and_which_pairs_interact(braided):
    chain = discretise(braided, sublinks=3)
    np.testing.assert_array_equal(chain.segment_index, np.repeat(np.arange(5), 3))
    i, j = chain.interacting_pairs()
    assert len(i) == 15 * 14 // 2 - 5 * 3  # all pairs but the three within each segment
    assert chain.interacting_pair_count() == len(i)
    assert np.all(chain.segment_index[i] != chain.segment_index[j])
    radius = np.sqrt(braided.segments[0].area_m2 / np.pi)
    np.testing.assert_allclose(chain.radii_m, radius)
    limits = chain.contact_distances((i, j))
    far = np.abs(i - j) > 1
    np.testing.assert_allclose(limits[far], 2 * radius)  # magnets' surfaces touch
    # Neighbours across a segment boundary: half their distance when straight, at most.
    assert np.all(limits[~far] <= 0.5 * chain.lengths_m[0] * (1 + 1e-12))
