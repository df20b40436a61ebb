"""Scene files: DESIGN.md's keys load into typed fields; bad ones are named by file and key."""

import hashlib
import json
import pathlib
import shutil

import numpy as np
import pytest
from tentacle_model.model import TentacleModel
from tentacle_planner.errors import PlanInputError
from tentacle_planner.scene import load_scene, parse_scene
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]
STRAIGHT = [[0.0, 0.0, 0.0], [0.030, 0.0, 0.0], [0.060, 0.0, 0.0]]
FULL = {
    'name': 'pancreatic_duct',
    'tentacle': '../tentacles/braided.yaml',
    'path': {'points_m': STRAIGHT},
    'insertion_steps_m': [0.010, 0.020, 0.030, 0.040, 0.050],
    'playback_step_m': 0.001,
    'coil': {'max_field_t': 0.020, 'max_total_field_t': 0.030, 'max_field_change_t': 0.015},
    'obstacles': [{'centre_m': [0.02, 0.01, 0.0], 'radius_m': 0.004}],
    'model': {'dof': 3, 'sublinks': 2, 'gravity_m_s2': [0, 0, -9.81], 'dipoles': True},
    'magnetisation': {'planar': True, 'max_neighbour_angle_deg': 60, 'distal_axial': True},
}
ZIGZAG = [[0.0, 0.0, 0.0], [0.030, 0.0, 0.0], [0.030342, 0.000940, 0.0],
          [0.030342 - 0.022981, 0.000940 + 0.019284, 0.0]]  # two 70 degree turns 1 mm apart
MINIMAL = {'tentacle': '../tentacles/braided.yaml', 'path': {'points_m': STRAIGHT},
           'insertion_steps_m': [0.05]}


@pytest.fixture
def folder(tmp_path):
    """Return the scenes folder of a tree like config/: tentacles/braided.yaml beside it."""
    (tmp_path / 'tentacles').mkdir()
    shutil.copy(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml',
                tmp_path / 'tentacles' / 'braided.yaml')
    (tmp_path / 'scenes').mkdir()
    return tmp_path / 'scenes'


def write(folder, document, name='scene.yaml'):
    file = folder / name
    file.write_text(document if isinstance(document, str) else yaml.safe_dump(document))
    return file


def changed(document, keys, value):
    doc = json.loads(json.dumps(document))
    target = doc
    for key in keys[:-1]:
        target = target[key]
    if value is KeyError:
        del target[keys[-1]]
    else:
        target[keys[-1]] = value
    return doc


def test_every_key_of_the_design_loads_typed(folder):
    file = write(folder, FULL)
    scene = load_scene(file)
    assert scene.name == 'pancreatic_duct'
    assert scene.sha256 == hashlib.sha256(file.read_bytes()).hexdigest()
    assert scene.source == file
    assert scene.tentacle_file == folder / '../tentacles/braided.yaml'
    assert scene.tentacle.name == 'braided_chapter5' and len(scene.tentacle.segments) == 5
    np.testing.assert_array_equal(scene.path.points_m, STRAIGHT)
    assert scene.insertion_steps_m == (0.010, 0.020, 0.030, 0.040, 0.050)
    assert scene.playback_step_m == 0.001
    assert (scene.coil.max_field_t, scene.coil.max_total_field_t,
            scene.coil.max_field_change_t) == (0.020, 0.030, 0.015)
    assert len(scene.obstacles) == 1 and scene.walls == ()
    np.testing.assert_array_equal(scene.obstacles[0].centre_m, [0.02, 0.01, 0.0])
    assert scene.obstacles[0].radius_m == 0.004
    assert (scene.model.dof, scene.model.sublinks, scene.model.gravity_m_s2,
            scene.model.dipoles) == (3, 2, (0.0, 0.0, -9.81), True)
    assert (scene.magnetisation.planar, scene.magnetisation.max_neighbour_angle_deg,
            scene.magnetisation.distal_axial) == (True, 60.0, True)
    model = scene.tentacle_model()
    assert isinstance(model, TentacleModel)
    assert (model.dof, model.sublinks, model.dipoles) == (3, 2, True)
    np.testing.assert_array_equal(model.gravity_m_s2, [0, 0, -9.81])
    assert scene.tentacle_model(dipoles=False).dipoles is False


def test_omitted_keys_are_no_limit_and_off(folder):
    scene = load_scene(write(folder, MINIMAL, 'short_duct.yaml'))
    assert scene.name == 'short_duct'  # the file's stem, as for a tentacle file
    assert scene.playback_step_m is None
    assert (scene.coil.max_field_t, scene.coil.max_total_field_t,
            scene.coil.max_field_change_t) == (None, None, None)
    assert scene.obstacles == () and scene.walls == ()
    assert (scene.model.dof, scene.model.sublinks, scene.model.gravity_m_s2,
            scene.model.dipoles) == (3, 1, (0.0, 0.0, 0.0), False)
    assert (scene.magnetisation.planar, scene.magnetisation.max_neighbour_angle_deg,
            scene.magnetisation.distal_axial) == (False, None, False)
    partial = load_scene(write(folder, dict(MINIMAL, coil={'max_field_t': 0.01},
                                            model={'sublinks': 3})))
    assert partial.coil.max_field_t == 0.01 and partial.coil.max_total_field_t is None
    assert partial.model.sublinks == 3 and partial.model.dof == 3


def test_walls_and_a_path_file_relative_to_the_scene(folder):
    (folder / 'paths').mkdir()
    np.save(folder / 'paths' / 'duct.npy', np.array(STRAIGHT))
    wall = [[0, 0.003, 0], [0.05, 0.003, 0]]
    scene = load_scene(write(folder, dict(MINIMAL, path={'file': 'paths/duct.npy'},
                                          obstacles={'walls': [{'points_m': wall}]})))
    np.testing.assert_array_equal(scene.path.points_m, STRAIGHT)
    assert scene.obstacles == () and len(scene.walls) == 1
    np.testing.assert_array_equal(scene.walls[0].points_m, [[0, 0.003, 0], [0.05, 0.003, 0]])


def test_a_slicer_path_is_placed_at_the_insertion_pose(folder):
    points = np.array([[10.0, 20.0, 30.0], [10.0, 20.0, 35.0], [10.0, 24.0, 60.0],
                       [10.0, 40.0, 85.0]])  # mm, LPS, a duct going up z and bending to +y
    lines = ['# Markups fiducial file version = 4.13', '# CoordinateSystem = LPS'] + \
        [f'{i},{x},{y},{z},0,0,0,1,1,1,0,F-{i},,' for i, (x, y, z) in enumerate(points)]
    (folder / 'duct.fcsv').write_text('\n'.join(lines) + '\n')
    scene = load_scene(write(folder, dict(MINIMAL, path={'file': 'duct.fcsv'})))
    moved = scene.path.points_m
    np.testing.assert_allclose(moved[:2], [[0, 0, 0], [0.005, 0, 0]], atol=1e-15)
    assert abs(moved[2, 2]) < 1e-15 and moved[2, 1] != 0  # its first bend in the base plane
    np.testing.assert_allclose(np.linalg.norm(np.diff(moved, axis=0), axis=1),
                               np.linalg.norm(np.diff(points, axis=0), axis=1) * 1e-3,
                               rtol=1e-12)


@pytest.mark.parametrize('keys, value, message', [
    (['colour'], 'red', r"top level: unknown key\(s\) \['colour'\]"),
    (['walls'], [], r"top level: unknown key\(s\) \['walls'\]"),
    (['coil', 'max_fields_t'], 0.01, r"coil: unknown key\(s\) \['max_fields_t'\]"),
    (['model', 'joints'], 3, r"model: unknown key\(s\) \['joints'\]"),
    (['magnetisation', 'axial'], True, r"magnetisation: unknown key\(s\) \['axial'\]"),
    (['obstacles', 0, 'radius'], 0.001, r"obstacles\[0\]: unknown key\(s\) \['radius'\]"),
    (['tentacle'], KeyError, r"top level: missing key\(s\) \['tentacle'\]"),
    (['path'], KeyError, r'top level: give either path \(a centreline to follow\) or coiling'),
    (['insertion_steps_m'], KeyError, r"top level: missing key\(s\) \['insertion_steps_m'\]"),
    (['obstacles', 0, 'radius_m'], KeyError, r"obstacles\[0\]: missing key\(s\) \['radius_m'\]"),
    (['name'], 7, 'name: expected a non-empty string, got 7'),
    (['tentacle'], 3, 'tentacle: expected a tentacle file name, got 3'),
    (['insertion_steps_m'], 0.01, 'insertion_steps_m: expected a non-empty list'),
    (['insertion_steps_m'], [], 'insertion_steps_m: expected a non-empty list'),
    (['insertion_steps_m', 2], 'deep', r"insertion_steps_m\[2\]: expected a number, got 'deep'"),
    (['insertion_steps_m', 0], -0.01, r'insertion_steps_m\[0\]: -0.01 must be positive'),
    (['insertion_steps_m', 0], 0, r'insertion_steps_m\[0\]: 0.0 must be positive'),
    (['insertion_steps_m', 2], 0.020, r'insertion_steps_m\[2\]: 0.02 m does not increase on '
                                      r'insertion_steps_m\[1\] \(0.02 m\)'),
    (['insertion_steps_m', 4], 0.035, r'insertion_steps_m\[4\]: 0.035 m does not increase'),
    (['insertion_steps_m', 4], 0.051, r'insertion_steps_m\[4\]: 0.051 m is more than the '
                                      'length of the tentacle, 0.05 m'),
    (['insertion_steps_m', 1], float('nan'), r'insertion_steps_m\[1\]: nan is not finite'),
    (['playback_step_m'], 0.0, 'playback_step_m: 0.0 must be positive'),
    (['playback_step_m'], 0.06, 'playback_step_m: 0.06 m is more than the deepest'),
    (['coil', 'max_field_t'], -0.02, 'coil.max_field_t: -0.02 must be positive'),
    (['coil', 'max_total_field_t'], True, 'coil.max_total_field_t: expected a number, got True'),
    (['coil'], [0.02], 'coil: expected a mapping, got list'),
    (['model', 'dof'], 2, 'model.dof: expected 1 .* or 3 .*, got 2'),
    (['model', 'dof'], True, 'model.dof: expected 1 .* or 3 .*, got True'),
    (['model', 'sublinks'], 0, 'model.sublinks: expected a whole number >= 1, got 0'),
    (['model', 'sublinks'], 1.5, 'model.sublinks: expected a whole number >= 1, got 1.5'),
    (['model', 'sublinks'], 100, 'model.sublinks: 500 links: the 3-DoF model solves at most 250'),
    (['model', 'gravity_m_s2'], [0, -9.81], r'model.gravity_m_s2: expected \[x, y, z\]'),
    (['model', 'dipoles'], 'no', "model.dipoles: expected true or false, got 'no'"),
    (['magnetisation', 'planar'], 1, 'magnetisation.planar: expected true or false, got 1'),
    (['magnetisation', 'max_neighbour_angle_deg'], 200, 'magnetisation.max_neighbour_angle_deg: '
                                                        '200 degrees is more than 180'),
    (['obstacles'], 'none', 'obstacles: expected a list of'),
    (['obstacles', 0, 'radius_m'], 0, r'obstacles\[0\].radius_m: 0.0 must be positive'),
    (['obstacles', 0, 'centre_m'], [0, 0], r'obstacles\[0\].centre_m: expected \[x, y, z\]'),
    (['obstacles'], {'walls': [{'points_m': []}]}, r'obstacles.walls\[0\].points_m: expected a '
                                                   'non-empty list'),
    (['obstacles'], {'wall': []}, r"obstacles: unknown key\(s\) \['wall'\]"),
    (['obstacles'], [{'centre_m': [0.02, 0.0005, 0], 'radius_m': 0.001}],
     r'obstacles\[0\]: the path runs through it between points 0 and 1'),
    (['path', 'frame'], 'world', "path.frame: 'world' is not one of"),
    (['path', 'points_m', 0], [0.0, 0.001, 0.0], 'path.points_m: point 0 .* is 1 mm from the '
                                                 'tentacle base position'),
    (['path', 'points_m', 2], [0.045, 0.0, 0.0], r'insertion_steps_m\[4\]: 50 mm is more than '
                                                 'the length of the path, 45 mm'),
    (['path', 'points_m', 2], [0.030, 0.0, 0.0], 'path.points_m: point 2 repeats point 1'),
    (['path', 'points_m'], [[0, 0, 0], [-0.03, 0.01, 0], [-0.06, 0.01, 0]],
     'path.points_m: point 0: the path leaves the insertion point 161.6 degrees off the '
     r'insertion direction \(over the first link, 5 mm\)'),
    (['path', 'points_m'], ZIGZAG, r'path.points_m: point [12]: the path turns 12\d.\d degrees '
                                   r'within two links \(5 mm each\)'),
])
def test_bad_keys_are_named_with_the_file(folder, keys, value, message):
    with pytest.raises(PlanInputError, match=f'scene.yaml: {message}'):
        load_scene(write(folder, changed(FULL, keys, value)))


def test_a_planar_model_needs_a_path_in_the_base_plane(folder):
    out = [[0.0, 0.0, 0.0], [0.030, 0.0, 0.0], [0.060, 0.0, 0.001]]
    load_scene(write(folder, dict(MINIMAL, path={'points_m': out})))  # 3-DoF: fine
    with pytest.raises(PlanInputError, match=r'scene.yaml: path.points_m: point 2 is 1 mm out '
                                             r'of the base plane: a planar model \(model.dof '
                                             r'1\)'):
        load_scene(write(folder, dict(MINIMAL, path={'points_m': out}, model={'dof': 1})))


def test_files_that_cannot_be_read_are_named(folder):
    with pytest.raises(PlanInputError, match='absent.yaml: No such file'):
        load_scene(folder / 'absent.yaml')
    with pytest.raises(PlanInputError, match='empty.yaml: empty file'):
        load_scene(write(folder, '', 'empty.yaml'))
    with pytest.raises(PlanInputError, match='bad.yaml: not valid YAML'):
        load_scene(write(folder, 'name: [duct', 'bad.yaml'))
    with pytest.raises(PlanInputError, match='list.yaml: top level: expected a mapping'):
        load_scene(write(folder, '- 1\n- 2\n', 'list.yaml'))
    with pytest.raises(PlanInputError, match=r'scene.yaml: tentacle: .*nobody.yaml: No such'):
        load_scene(write(folder, dict(MINIMAL, tentacle='nobody.yaml')))
    (folder / 'broken.yaml').write_text('segments: []\n')
    with pytest.raises(PlanInputError, match=r'scene.yaml: tentacle: .*broken.yaml: segments: '
                                             'expected a non-empty list'):
        load_scene(write(folder, dict(MINIMAL, tentacle='broken.yaml')))
    with pytest.raises(PlanInputError, match=r'scene.yaml: path.file: .*duct.csv: No such'):
        load_scene(write(folder, dict(MINIMAL, path={'file': 'duct.csv'})))
    with pytest.raises(PlanInputError, match='huge.yaml: larger than 64 KiB'):
        load_scene(write(folder, '#' * (65 * 1024), 'huge.yaml'))


def test_yaml_1_1_number_strings_are_numbers(folder):
    # PyYAML reads 1e-2 (no dot) as a string: accepted as the number it spells.
    text = yaml.safe_dump(MINIMAL).replace('- 0.05', '- 5e-2')
    assert '5e-2' in text
    assert load_scene(write(folder, text)).insertion_steps_m == (0.05,)


def test_parse_scene_takes_a_document(folder):
    scene = parse_scene(MINIMAL, folder / 'virtual.yaml', 'abc')
    assert scene.name == 'virtual' and scene.sha256 == 'abc'


COILING = {'tentacle': '../tentacles/vsr.yaml', 'coiling': {'radius_m': 0.0075},
           'insertion_steps_m': [0.06], 'backbone_steps_m': [0.05, 0.045, 0.04],
           'model': {'dof': 1}, 'magnetisation': {'given': True}}


@pytest.fixture
def vsr_folder(folder):
    shutil.copy(ROOT / 'config' / 'tentacles' / 'vsr_chapter6.yaml',
                folder.parent / 'tentacles' / 'vsr.yaml')
    return folder


def test_a_coiling_target_is_straight_to_the_backbone_then_an_arc(vsr_folder):
    scene = load_scene(write(vsr_folder, COILING))
    assert scene.insertion_steps_m == (0.06,) * 3
    assert scene.backbone_steps_m == (0.05, 0.045, 0.04)
    np.testing.assert_allclose(scene.own_directions(), [
        s.magnetisation_a_per_m / np.linalg.norm(s.magnetisation_a_per_m)
        for s in scene.tentacle.segments])
    path = scene.target_path(0.06, 0.045)
    s = path.arc_lengths_m
    straight, arc = path.points_m[s <= 0.045], path.points_m[s >= 0.045]
    np.testing.assert_allclose(straight[:, 1:], 0.0, atol=1e-15)     # along the base x axis
    np.testing.assert_allclose(straight[:, 0], s[s <= 0.045], atol=1e-12)
    centre = np.array([0.045, 0.0075, 0.0])                            # turning towards +y
    np.testing.assert_allclose(np.linalg.norm(arc - centre, axis=1), 0.0075, rtol=1e-12)
    assert path.length_m == pytest.approx(0.06, abs=1e-3)
    # The picture's and the schedule's path is the deepest step's target.
    np.testing.assert_allclose(scene.path.points_m, scene.target_path(0.06, 0.04).points_m)


@pytest.mark.parametrize('keys, value, message', [
    (['backbone_steps_m'], [0.05, 0.07], r'backbone_steps_m\[1\]: 0.07 m reaches past'),
    (['insertion_steps_m'], [0.06, 0.06], '3 backbone steps for 2 insertion steps'),
    (['backbone_steps_m'], KeyError, 'a coiling target needs backbone_steps_m'),
    (['coiling', 'side'], 0, r'coiling.side: expected 1 \(towards the base normal\) or -1'),
    (['path'], {'points_m': STRAIGHT}, 'give either path'),
    (['playback_step_m'], 0.001, 'dense playback of a backbone schedule is not supported'),
])
def test_bad_backbone_schedules_are_named(vsr_folder, keys, value, message):
    with pytest.raises(PlanInputError, match=message):
        load_scene(write(vsr_folder, changed(COILING, keys, value)))


def test_a_backbone_schedule_needs_a_backbone(folder):
    document = dict(MINIMAL, backbone_steps_m=[0.01])
    with pytest.raises(PlanInputError, match='backbone_steps_m: the tentacle .* has no backbone'):
        load_scene(write(folder, document))
