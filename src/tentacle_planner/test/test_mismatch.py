"""A scene's mismatch block: read strictly, and applied as it says."""

import math
import pathlib

import numpy as np
import pytest
from tentacle_planner.errors import PlanInputError
from tentacle_planner.mismatch import Mismatch
from tentacle_planner.scene import load_scene
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]
DUCT = ROOT / 'config' / 'scenes' / 'pancreatic_duct.yaml'


def scene_with(tmp_path, mismatch=None):
    """Return the duct scene with another mismatch block (None: without one)."""
    document = yaml.safe_load(DUCT.read_text())
    document['tentacle'] = str(DUCT.parent / document['tentacle'])
    document.pop('mismatch', None)
    if mismatch is not None:
        document['mismatch'] = mismatch
    path = tmp_path / 'scene.yaml'
    path.write_text(yaml.safe_dump(document))
    return load_scene(path)


def test_no_block_is_no_mismatch(tmp_path):
    scene = scene_with(tmp_path)
    assert scene.mismatch == Mismatch() and scene.mismatch.describe() == 'none'
    spec = scene.mismatch.tentacle(scene.tentacle)
    for a, b in zip(scene.tentacle.segments, spec.segments):
        assert a.modulus_pa == b.modulus_pa
        assert np.array_equal(a.magnetisation_a_per_m, b.magnetisation_a_per_m)
    assert np.array_equal(spec.base_rotation, scene.tentacle.base_rotation)
    assert np.array_equal(scene.mismatch.actuation_matrix(np.eye(3)), np.eye(3))


def test_the_block_changes_the_tentacle_and_the_coils_as_it_says(tmp_path):
    scene = scene_with(tmp_path, {'stiffness_factor': 0.8, 'remanence_factor': 1.05,
                                  'insertion_offset_m': [0.0, 3e-4, 0.0],
                                  'insertion_angle_deg': 1.5,
                                  'actuation_matrix_factor': [1.03, 0.97, 1.0]})
    nominal, true = scene.tentacle, scene.mismatch.tentacle(scene.tentacle)
    for a, b in zip(nominal.segments, true.segments):
        assert np.allclose(np.array(b.modulus_pa), 0.8 * np.array(a.modulus_pa))
        assert np.allclose(b.magnetisation_a_per_m, 1.05 * np.asarray(a.magnetisation_a_per_m))
    assert true.base_position_m - nominal.base_position_m == pytest.approx(
        np.array([0.0, 3e-4, 0.0]))
    cos = nominal.base_rotation[:, 0] @ true.base_rotation[:, 0]
    assert math.degrees(math.acos(min(cos, 1.0))) == pytest.approx(1.5)
    a = np.arange(1.0, 10.0).reshape(3, 3)
    assert scene.mismatch.actuation_matrix(a) == pytest.approx(a * [1.03, 0.97, 1.0])
    assert 'stiffness x0.8' in scene.mismatch.describe()


@pytest.mark.parametrize('block, message', [
    ({'stiffness_factor': 0.0}, r'mismatch.stiffness_factor: 0.0 must be positive'),
    ({'stiffness_factor': 80}, r'mismatch.stiffness_factor: 80 is outside \[0.2, 5\]'),
    ({'insertion_offset_m': [0.02, 0, 0]}, 'mismatch.insertion_offset_m: 20 mm is more'),
    ({'actuation_matrix_factor': [1, 1]}, r'mismatch.actuation_matrix_factor: expected'),
    ({'stifness_factor': 0.9}, r"mismatch: unknown key\(s\) \['stifness_factor'\]"),
])
def test_a_bad_block_is_refused_naming_the_key(tmp_path, block, message):
    with pytest.raises(PlanInputError, match=message):
        scene_with(tmp_path, block)


def test_the_duct_scenes_state_a_realistic_mismatch():
    for name in ('pancreatic_duct', 'bile_duct'):
        mismatch = load_scene(DUCT.parent / f'{name}.yaml').mismatch
        assert mismatch.describe() == ('stiffness x0.9, remanence x0.95, insertion point moved '
                                       'by [0, 0.3, 0] mm, insertion turned 1.5 deg, coils '
                                       'x[1.03, 0.97, 1]')
