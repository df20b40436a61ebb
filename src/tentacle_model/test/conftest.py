"""Shared fixtures: the validation cantilever and its closed-form quantities."""

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
