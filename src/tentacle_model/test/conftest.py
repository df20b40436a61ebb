"""Shared fixtures: the validation cantilever and its closed-form quantities; a dense load."""

import pathlib

import numpy as np
import pytest
from tentacle_model.tentacle_spec import load_tentacle

ROOT = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope='session')
def cantilever():
    """Return (spec, L m, EI N m^2, M A in A m) of config/tentacles/cantilever.yaml."""
    spec = load_tentacle(ROOT / 'config' / 'tentacles' / 'cantilever.yaml')
    segment = spec.segments[0]
    return (spec, segment.length_m, segment.bend_stiffness_n_m2[0],
            float(np.linalg.norm(segment.magnetisation_a_per_m)) * segment.area_m2)


@pytest.fixture(scope='session')
def braided():
    """Return the spec of config/tentacles/braided_chapter5.yaml (5 segments, 3-DoF)."""
    return load_tentacle(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml')


@pytest.fixture
def dense_load():
    """
    Return make(n, seed), which makes a link load (link_loads.py) with a dense Hessian.

    The load is quadratic in every link's moment and centre with a random Hessian, coupling
    every link with every other.
    """
    from tentacle_model import dipoles

    def make(n, seed):
        rng = np.random.default_rng(seed)
        size = 6 * n
        hess = rng.normal(size=(size, size))
        hess = hess + hess.T
        origin, slope = rng.normal(size=size), rng.normal(size=size)
        scale = np.repeat([1.0, 1e3], 3 * n)       # centres in mm: terms of one size

        def load(moments, centres, hessian):
            x = scale * np.concatenate([moments.reshape(-1), centres.reshape(-1)]) - origin
            grad = scale * (slope + hess @ x)
            return dipoles.Interaction(float(slope @ x + 0.5 * x @ hess @ x),
                                       grad[:3 * n].reshape(n, 3), grad[3 * n:].reshape(n, 3),
                                       scale[:, None] * hess * scale if hessian else None)
        return load
    return make
