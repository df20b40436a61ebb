"""Path files in every format, frames, sampling by arc length, follow-the-leader targets."""

import json
import math
import pathlib

import numpy as np
import pytest
from tentacle_model.chain import discretise
from tentacle_model.tentacle_spec import load_tentacle, parse_tentacle
from tentacle_planner import paths
from tentacle_planner.errors import PlanInputError
from tentacle_planner.paths import Path

ROOT = pathlib.Path(__file__).resolve().parents[3]
BASE = (np.zeros(3), np.eye(3))  # the shipped tentacles: at the origin, along x, normal y


def known_points(step_m=0.0005):
    """Return a 3D path (k, 3) m: 5 mm straight along x, then bending to +y and then up z."""
    s = np.arange(0.0, 0.060 + step_m / 2, step_m)
    heading = np.where(s < 0.005, 0.0, (s - 0.005) / 0.040)      # in-plane, towards +y
    elevation = np.where(s < 0.020, 0.0, (s - 0.020) / 0.080)    # then out of the plane
    mids = (heading[:-1] + heading[1:]) / 2, (elevation[:-1] + elevation[1:]) / 2
    steps = step_m * np.column_stack([np.cos(mids[1]) * np.cos(mids[0]),
                                      np.cos(mids[1]) * np.sin(mids[0]), np.sin(mids[1])])
    return np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])


def random_pose(seed):
    rng = np.random.default_rng(seed)
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(rotation) < 0:
        rotation[:, 0] *= -1
    return rotation, rng.normal(0, 0.05, 3)


def write_csv(file, points, unit='mm', extra=False):
    scale = 1.0 / paths.UNITS_M[unit]
    header = ['label'] * extra + [f'{a}_{unit}' for a in 'xyz']
    lines = ['# exported for a test', ','.join(header)]
    for i, p in enumerate(points):
        lines.append(','.join([f'P{i}'] * extra + [repr(float(v * scale)) for v in p]))
    file.write_text('\n'.join(lines) + '\n')
    return file


def write_markups(file, ras_points, system='LPS', unit='mm', kind='Curve', units=None):
    values = np.array(ras_points) / paths.UNITS_M[unit]
    if system == 'LPS':
        values[:, :2] *= -1
    markup = {'type': kind, 'coordinateSystem': system,
              'coordinateUnits': unit if units is None else units,
              'controlPoints': [{'id': str(i + 1), 'label': f'P-{i + 1}',
                                 'position': [float(v) for v in p], 'positionStatus': 'defined'}
                                for i, p in enumerate(values)]}
    file.write_text(json.dumps({'@schema': 'https://raw.githubusercontent.com/slicer/slicer/'
                                'master/Modules/Loadable/Markups/Resources/Schema/'
                                'markups-schema-v1.0.3.json#', 'markups': [markup]}))
    return file


def write_fcsv(file, ras_points, system='LPS'):
    values = np.array(ras_points) * 1e3
    if system in ('LPS', '1'):
        values[:, :2] *= -1
    lines = ['# Markups fiducial file version = 4.13', f'# CoordinateSystem = {system}',
             '# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID,'
             'positionStatus,autoCreated']
    for i, p in enumerate(values):
        x, y, z = (repr(float(v)) for v in p)
        lines.append(f'{i + 1},{x},{y},{z},0,0,0,1,1,1,0,F-{i + 1},,,2,0')
    file.write_text('\n'.join(lines) + '\n')
    return file


# Formats round-trip a known path.

@pytest.mark.parametrize('unit', ['m', 'mm', 'um'])
def test_csv_round_trips_in_every_unit(tmp_path, unit):
    points = known_points()
    read, frame = paths.read_path_file(write_csv(tmp_path / 'p.csv', points, unit))
    assert frame == 'rig'
    np.testing.assert_allclose(read, points, rtol=0, atol=1e-15)


def test_csv_ignores_other_columns_and_reads_units_case_and_spacing(tmp_path):
    points = known_points()
    read, _ = paths.read_path_file(write_csv(tmp_path / 'p.csv', points, 'mm', extra=True))
    np.testing.assert_allclose(read, points, rtol=0, atol=1e-15)
    (tmp_path / 'q.csv').write_text(' X_mm , Y_mm , Z_mm \n1, 2, 3\n4, 5, 6\n')
    read, _ = paths.read_path_file(tmp_path / 'q.csv')
    np.testing.assert_allclose(read, [[1e-3, 2e-3, 3e-3], [4e-3, 5e-3, 6e-3]], atol=1e-18)


def test_npy_round_trips(tmp_path):
    points = known_points()
    np.save(tmp_path / 'p.npy', points)
    read, frame = paths.read_path_file(tmp_path / 'p.npy')
    assert frame == 'rig'
    np.testing.assert_array_equal(read, points)
    np.save(tmp_path / 'i.npy', np.array([[0, 0, 0], [1, 0, 0]], dtype=np.int32))
    np.testing.assert_array_equal(paths.read_path_file(tmp_path / 'i.npy')[0],
                                  [[0, 0, 0], [1, 0, 0]])


@pytest.mark.parametrize('system', ['LPS', 'RAS'])
@pytest.mark.parametrize('unit', ['mm', 'um', 'm'])
def test_markups_round_trip_in_either_system_and_unit(tmp_path, system, unit):
    points = known_points()
    file = write_markups(tmp_path / 'p.mrk.json', points, system, unit)
    read, frame = paths.read_path_file(file)
    assert frame == 'image'
    np.testing.assert_allclose(read, points, rtol=0, atol=1e-15)


def test_markups_point_lists_ucum_units_and_defaults(tmp_path):
    points = known_points()[::10]
    file = write_markups(tmp_path / 'p.mrk.json', points, kind='Fiducial',
                         units=['um', 'UCUM', 'micrometer'], unit='um')
    np.testing.assert_allclose(paths.read_path_file(file)[0], points, rtol=0, atol=1e-15)
    # Without coordinateSystem and coordinateUnits: LPS and mm, the schema's defaults.
    doc = json.loads(write_markups(tmp_path / 'd.mrk.json', points).read_text())
    del doc['markups'][0]['coordinateSystem'], doc['markups'][0]['coordinateUnits']
    (tmp_path / 'd.mrk.json').write_text(json.dumps(doc))
    np.testing.assert_allclose(paths.read_path_file(tmp_path / 'd.mrk.json')[0], points,
                               rtol=0, atol=1e-15)


def test_markups_reads_the_first_markup_only(tmp_path):
    doc = json.loads(write_markups(tmp_path / 'p.mrk.json', known_points()).read_text())
    doc['markups'].append({'type': 'ROI', 'controlPoints': []})
    (tmp_path / 'p.mrk.json').write_text(json.dumps(doc))
    assert len(paths.read_path_file(tmp_path / 'p.mrk.json')[0]) == len(known_points())


@pytest.mark.parametrize('system', ['LPS', 'RAS', '0', '1'])
def test_fcsv_round_trips_in_either_system(tmp_path, system):
    points = known_points()
    read, frame = paths.read_path_file(write_fcsv(tmp_path / 'p.fcsv', points, system))
    assert frame == 'image'
    np.testing.assert_allclose(read, points, rtol=0, atol=1e-15)


def test_lps_negates_x_and_y_of_the_numbers_in_the_file(tmp_path):
    (tmp_path / 'l.fcsv').write_text('# CoordinateSystem = LPS\n1,1,2,3\n2,4,5,6\n')
    (tmp_path / 'r.fcsv').write_text('# CoordinateSystem = RAS\n1,1,2,3\n2,4,5,6\n')
    lps = paths.read_path_file(tmp_path / 'l.fcsv')[0]
    ras = paths.read_path_file(tmp_path / 'r.fcsv')[0]
    np.testing.assert_allclose(ras, [[1e-3, 2e-3, 3e-3], [4e-3, 5e-3, 6e-3]], atol=1e-18)
    np.testing.assert_allclose(lps, ras * [-1, -1, 1], atol=1e-18)
    doc = {'markups': [{'type': 'Curve', 'coordinateSystem': 'LPS', 'controlPoints': [
        {'position': [1, 2, 3]}, {'position': [4, 5, 6]}]}]}
    (tmp_path / 'l.mrk.json').write_text(json.dumps(doc))
    np.testing.assert_allclose(paths.read_path_file(tmp_path / 'l.mrk.json')[0], lps,
                               atol=1e-18)


def test_scene_blocks_load_each_format_into_the_rig_frame(tmp_path):
    points = known_points()
    np.save(tmp_path / 'p.npy', points)
    write_csv(tmp_path / 'p.csv', points)
    write_markups(tmp_path / 'p.mrk.json', points, 'LPS')
    write_fcsv(tmp_path / 'p.fcsv', points, 'RAS')
    blocks = [{'points_m': points.tolist()}, {'file': 'p.npy'}, {'file': 'p.csv'},
              {'file': 'p.mrk.json'}, {'file': 'p.fcsv'}, {'file': 'p.mrk.json', 'frame': 'rig'}]
    for block in blocks:
        path = paths.load_path(block, *BASE, tmp_path, 'scene.yaml')
        np.testing.assert_allclose(path.points_m, points, rtol=0, atol=1e-14, err_msg=block)


# Frames.

@pytest.mark.parametrize('seed', range(3))
def test_an_image_path_is_moved_onto_the_insertion_pose(tmp_path, seed):
    points = known_points()
    rotation, shift = random_pose(seed)
    image = points @ rotation.T + shift
    write_markups(tmp_path / 'p.mrk.json', image, 'LPS')
    # A tentacle whose base is elsewhere, turned: the path must start there, along it.
    base_rotation, base_position = random_pose(seed + 10)
    path = paths.load_path({'file': 'p.mrk.json'}, base_position, base_rotation, tmp_path)
    np.testing.assert_allclose(path.points_m, points @ base_rotation.T + base_position,
                               rtol=0, atol=1e-13)


def test_an_image_path_bends_first_towards_the_base_normal():
    # A path bending to -z first, in some image frame: moved so that it bends to +y.
    bend = np.array([[0, 0, 0], [0.003, 0, 0], [0.006, 0, -0.001], [0.008, 0.0005, -0.003]])
    moved = paths.image_to_rig(Path(bend), *BASE).points_m
    np.testing.assert_allclose(moved[1], [0.003, 0, 0], atol=1e-15)
    assert moved[2][1] > 0 and abs(moved[2][2]) < 1e-15
    # Straight paths have no bend: the smallest rotation aligns them.
    straight = paths.image_to_rig(Path([[1, 1, 1], [1, 1, 1.01]]), *BASE).points_m
    np.testing.assert_allclose(straight, [[0, 0, 0], [0.01, 0, 0]], atol=1e-15)


def test_a_rig_frame_path_starts_at_the_base_position():
    near = known_points() + [0.0004, 0.0, 0.0]
    assert paths.place(Path(near), 'rig', *BASE).length_m > 0
    far = known_points() + [0.0, 0.0006, 0.0]
    with pytest.raises(PlanInputError, match=r'scene.yaml: path.points_m: point 0 .* is '
                                             r'0.6 mm from the tentacle base position'):
        paths.load_path({'points_m': far.tolist()}, *BASE, '.', 'scene.yaml')
    # frame: image puts it there.
    path = paths.load_path({'points_m': far.tolist(), 'frame': 'image'}, *BASE)
    np.testing.assert_allclose(path.points_m, known_points(), atol=1e-14)


# Sampling by arc length.

def test_sampling_is_exact_on_a_polyline():
    rng = np.random.default_rng(5)
    vertices = np.cumsum(rng.uniform(0.5e-3, 2e-3, (12, 3)) * [1, 0.6, 0.3], axis=0)
    path = Path(vertices)
    lengths = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
    assert path.length_m == pytest.approx(lengths.sum(), rel=1e-15)
    np.testing.assert_array_equal(path.at(path.arc_lengths_m), vertices)  # bit for bit
    # Anywhere else: on the segment, at the right fraction of it.
    s = rng.uniform(0, path.length_m, 200)
    k = np.searchsorted(path.arc_lengths_m, s) - 1
    f = (s - path.arc_lengths_m[k]) / lengths[k]
    expected = vertices[k] + f[:, None] * (vertices[k + 1] - vertices[k])
    np.testing.assert_allclose(path.at(s), expected, rtol=0, atol=1e-17)
    # Resampled together with its vertices, a polyline is the same polyline.
    dense = path.resample(1e-4)
    assert np.all(np.diff(np.linalg.norm(np.diff(dense, axis=0), axis=1)) < 1e-4)
    merged = Path(path.at(np.union1d(path.arc_lengths_m,
                                     np.linspace(0, path.length_m, 97)[1:-1])))
    assert merged.length_m == pytest.approx(path.length_m, rel=1e-14)
    np.testing.assert_allclose(merged.at(s), path.at(s), rtol=0, atol=1e-17)
    assert path.at(0.5 * path.length_m).shape == (3,)
    with pytest.raises(PlanInputError, match='arc length .* is outside the path'):
        path.at([path.length_m * 1.01])


# Follow-the-leader targets.

@pytest.fixture(scope='module')
def braided():
    return load_tentacle(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml')


def test_targets_on_a_straight_path(braided):
    path = Path([[0, 0, 0], [0.060, 0, 0]])
    full = paths.targets(path, discretise(braided, 0.050, 1), 0.050)
    np.testing.assert_allclose(full[:, 0], [0, 0.01, 0.02, 0.03, 0.04, 0.05], atol=1e-16)
    assert np.all(full[:, 1:] == 0)
    # 25 mm in: half of segment 2 (a 5 mm link) at the base, then segments 3 and 4.
    part = paths.targets(path, discretise(braided, 0.025, 1), 0.025)
    np.testing.assert_allclose(part[:, 0], [0, 0.005, 0.015, 0.025], atol=1e-16)
    # Sub-links: 2 per segment, 33.3 mm in.
    sub = paths.targets(path, discretise(braided, 0.0333, 2), 0.0333)
    np.testing.assert_allclose(sub[:, 0], [0, 0.0033, 0.0083, 0.0133, 0.0183, 0.0233, 0.0283,
                                           0.0333], atol=1e-15)


def test_targets_on_an_arc_by_hand():
    # Vertices on a circle of radius R every 20 degrees; links one chord long.
    radius, step = 0.030, math.radians(20.0)
    chord = 2 * radius * math.sin(step / 2)
    angle = step * np.arange(6)
    vertices = radius * np.column_stack([np.sin(angle), 1 - np.cos(angle), np.zeros(6)])
    segment = {'length_m': chord, 'section': {'diameter_m': 0.002},
               'youngs_modulus_pa': 1e5, 'density_kg_m3': 1000.0}
    spec = parse_tentacle({'segments': [segment] * 4})
    path = Path(vertices)
    full = paths.targets(path, discretise(spec, 4 * chord), 4 * chord)
    np.testing.assert_allclose(full, vertices[:5], rtol=0, atol=1e-16)
    # 2.5 links in: the joints at arc 0, 0.5, 1.5 and the tip at 2.5 chords along the path.
    part = paths.targets(path, discretise(spec, 2.5 * chord), 2.5 * chord)
    expected = [vertices[0], (vertices[0] + vertices[1]) / 2, (vertices[1] + vertices[2]) / 2,
                (vertices[2] + vertices[3]) / 2]
    np.testing.assert_allclose(part, expected, rtol=0, atol=1e-16)


def test_targets_refuse_a_path_too_short_or_a_chain_of_another_length(braided):
    path = Path([[0, 0, 0], [0.040, 0, 0]], 'short.csv')
    with pytest.raises(PlanInputError, match='short.csv: the path is 40 mm long, shorter '
                                             'than the 50 mm inserted'):
        paths.targets(path, discretise(braided, 0.050), 0.050)
    with pytest.raises(ValueError, match='the chain has 0.03 m free, not the 0.02 m'):
        paths.targets(path, discretise(braided, 0.030), 0.020)


# Bad inputs: each names the file and the point or key.

def test_missing_and_empty_files_are_named(tmp_path):
    with pytest.raises(PlanInputError, match='nowhere.csv: No such file'):
        paths.read_path_file(tmp_path / 'nowhere.csv')
    for name in ('e.csv', 'e.mrk.json', 'e.fcsv', 'e.npy'):
        (tmp_path / name).write_text('  \n')
        with pytest.raises(PlanInputError, match=f'{name}: empty file'):
            paths.read_path_file(tmp_path / name)
    (tmp_path / 'c.csv').write_text('# only a comment\n')
    with pytest.raises(PlanInputError, match='c.csv: empty file'):
        paths.read_path_file(tmp_path / 'c.csv')
    (tmp_path / 'h.csv').write_text('x_mm,y_mm,z_mm\n')
    with pytest.raises(PlanInputError, match=r'h.csv: no points \(only a header\)'):
        paths.read_path_file(tmp_path / 'h.csv')
    np.save(tmp_path / 'z.npy', np.zeros((0, 3)))
    with pytest.raises(PlanInputError, match='z.npy: no points'):
        paths.read_path_file(tmp_path / 'z.npy')
    (tmp_path / 'n.fcsv').write_text('# CoordinateSystem = LPS\n')
    with pytest.raises(PlanInputError, match='n.fcsv: no points'):
        paths.read_path_file(tmp_path / 'n.fcsv')
    write_markups(tmp_path / 'n.mrk.json', np.zeros((0, 3)))
    with pytest.raises(PlanInputError, match=r'n.mrk.json: markups\[0\].controlPoints: no '
                                             'points'):
        paths.read_path_file(tmp_path / 'n.mrk.json')
    with pytest.raises(PlanInputError, match='p.txt: unknown kind of path file'):
        paths.read_path_file(tmp_path / 'p.txt')


@pytest.mark.parametrize('text, message', [
    ('x_mm,y_mm\n1,2\n', r'line 1: the header .* has no z column'),
    ('x,y_mm,z_mm\n1,2,3\n', "line 1: column 'x' names no unit"),
    ('x_in,y_in,z_in\n1,2,3\n', "line 1: column 'x_in': unknown unit 'in'"),
    ('x_mm,y_mm,z_mm,x_m\n1,2,3,4\n', 'line 1: two x columns'),
    ('# c\nx_mm,y_mm,z_mm\n1,2,3\n4,5\n', r'line 4 \(point 1\): 2 fields, the header has 3'),
    ('x_mm,y_mm,z_mm\n1,2,3\n4,five,6\n', r"line 3 \(point 1\): y_mm 'five' is not a number"),
    ('x_mm,y_mm,z_mm\n"1,2,3\n', 'line 2: malformed CSV'),
])
def test_malformed_csv_is_named_by_line(tmp_path, text, message):
    (tmp_path / 'p.csv').write_text(text)
    with pytest.raises(PlanInputError, match=f'p.csv: {message}'):
        paths.read_path_file(tmp_path / 'p.csv')


def markups_with(tmp_path, change):
    doc = json.loads(write_markups(tmp_path / 'p.mrk.json', known_points()[:5]).read_text())
    change(doc['markups'][0])
    (tmp_path / 'p.mrk.json').write_text(json.dumps(doc))
    return tmp_path / 'p.mrk.json'


@pytest.mark.parametrize('change, message', [
    (lambda m: m.update(coordinateUnits='cm'),
     r"markups\[0\].coordinateUnits: unknown unit 'cm'"),
    (lambda m: m.update(coordinateUnits=['mm', 'SRT', 'millimeter']),
     r'markups\[0\].coordinateUnits: unknown unit'),
    (lambda m: m.update(coordinateSystem='XYZ'),
     r"markups\[0\].coordinateSystem: unknown coordinate system 'XYZ'"),
    (lambda m: m.update(type='ClosedCurve'), r"markups\[0\].type: 'ClosedCurve' is not a path"),
    (lambda m: m['controlPoints'][2].update(position=''),
     r"markups\[0\].controlPoints\[2\] \('P-3'\): the position of the point is undefined"),
    (lambda m: m['controlPoints'][3].update(positionStatus='undefined'),
     r"markups\[0\].controlPoints\[3\] \('P-4'\): the position of the point is undefined "
     r"\(positionStatus 'undefined'"),
    (lambda m: m['controlPoints'][1].update(position=[1, 2]),
     r"markups\[0\].controlPoints\[1\] \('P-2'\).position: expected three numbers"),
    (lambda m: m.update(controlPoints={}), r'markups\[0\].controlPoints: expected a list'),
])
def test_bad_markups_are_named_by_key_and_point(tmp_path, change, message):
    with pytest.raises(PlanInputError, match=f'p.mrk.json: {message}'):
        paths.read_path_file(markups_with(tmp_path, change))


def test_malformed_json_and_non_markups_are_named(tmp_path):
    (tmp_path / 'bad.mrk.json').write_text('{"markups": [{"type": "Curve",}]}')
    with pytest.raises(PlanInputError, match='bad.mrk.json: not valid JSON: .* line 1 column'):
        paths.read_path_file(tmp_path / 'bad.mrk.json')
    (tmp_path / 'other.json').write_text('{"points": []}')
    with pytest.raises(PlanInputError, match='other.json: not a Slicer markups file'):
        paths.read_path_file(tmp_path / 'other.json')
    (tmp_path / 'none.json').write_text('{"markups": []}')
    with pytest.raises(PlanInputError, match='none.json: markups: empty list'):
        paths.read_path_file(tmp_path / 'none.json')


@pytest.mark.parametrize('text, message', [
    ('# CoordinateSystem = 2\n1,1,2,3\n', "line 1: unknown coordinate system '2'"),
    ('# CoordinateSystem = IJK\n1,1,2,3\n', "line 1: unknown coordinate system 'IJK'"),
    ('# columns = label,x,y,z\n1,1,2,3\n', "line 1: columns 'label,x,y,z'"),
    ('# CoordinateSystem = LPS\n1,1,2\n', r'line 2 \(point 0\): expected id,x,y,z'),
    ('# CoordinateSystem = LPS\n1,1,2,3\n2,a,b,c\n', r'line 3 \(point 1\): x, y, z'),
    ('1,1,2,3,0,0,0,1,1,1,0,F-1,,,2,0\n2,1,2,4,0,0,0,1,1,1,0,F-2,,,0,0\n',
     r'line 2 \(point 1\): the position of the point is undefined \(positionStatus 0'),
])
def test_bad_fcsv_is_named_by_line(tmp_path, text, message):
    (tmp_path / 'p.fcsv').write_text(text)
    with pytest.raises(PlanInputError, match=f'p.fcsv: {message}'):
        paths.read_path_file(tmp_path / 'p.fcsv')


def test_bad_npy_is_named(tmp_path):
    np.save(tmp_path / 'shape.npy', np.zeros((4, 2)))
    with pytest.raises(PlanInputError, match=r'shape.npy: expected a \(k, 3\) array'):
        paths.read_path_file(tmp_path / 'shape.npy')
    np.save(tmp_path / 'text.npy', np.array([['a', 'b', 'c']]))
    with pytest.raises(PlanInputError, match='text.npy: expected an array of real numbers'):
        paths.read_path_file(tmp_path / 'text.npy')
    np.save(tmp_path / 'obj.npy', np.array([[1, None, 2]], dtype=object), allow_pickle=True)
    with pytest.raises(PlanInputError, match='obj.npy: not a readable .npy array'):
        paths.read_path_file(tmp_path / 'obj.npy')
    (tmp_path / 'junk.npy').write_bytes(b'not numpy at all')
    with pytest.raises(PlanInputError, match='junk.npy: not a readable .npy array'):
        paths.read_path_file(tmp_path / 'junk.npy')


@pytest.mark.parametrize('points, message', [
    ([[0, 0, 0], [1e-3, 0, 0], [float('nan'), 0, 0]], r'point 2: \[nan, 0.0, 0.0\] is not '
                                                      'finite'),
    ([[0, 0, 0], [1e-3, float('inf'), 0], [2e-3, 0, 0]], 'point 1: .* is not finite'),
    ([[0, 0, 0], [1e-3, 0, 0], [2e-3, 0, 0], [2e-3, 0, 0]], 'point 3 repeats point 2'),
    ([[0, 0, 0], [1e-3, 0, 0], [0.5e-3, 0.1e-3, 0]],
     'point 1: the path turns 168.7 degrees there, more than the 120'),
    ([[0, 0, 0]], 'a path needs at least two points, got 1'),
    ([[0, 0], [1, 1]], r'expected points of three coordinates, got an array of shape \(2, 2\)'),
])
def test_bad_points_are_named(points, message):
    with pytest.raises(PlanInputError, match=f'duct.csv: {message}'):
        Path(points, 'duct.csv')


def test_bad_points_in_files_name_the_scene_key_file_and_point(tmp_path):
    points = known_points()
    points[7] = np.nan
    np.save(tmp_path / 'p.npy', points)
    with pytest.raises(PlanInputError, match=r'scene.yaml: path.file: .*p.npy: point 7: '):
        paths.load_path({'file': 'p.npy'}, *BASE, tmp_path, 'scene.yaml')
    write_csv(tmp_path / 'p.csv', np.vstack([points[:3], points[2:3], points[3:6]]))
    with pytest.raises(PlanInputError, match=r'scene.yaml: path.file: .*p.csv: point 3 '
                                             'repeats point 2'):
        paths.load_path({'file': 'p.csv'}, *BASE, tmp_path, 'scene.yaml')
    with pytest.raises(PlanInputError, match=r'scene.yaml: path.file: .*gone.fcsv: No such'):
        paths.load_path({'file': 'gone.fcsv'}, *BASE, tmp_path, 'scene.yaml')


@pytest.mark.parametrize('block, message', [
    ({'points_m': [[0, 0, 0], [0.01, 0, 0]], 'file': 'p.csv'},
     'path: give either points_m or file'),
    ({}, 'path: give either points_m or file'),
    ({'points': [[0, 0, 0]]}, r"path: unknown key\(s\) \['points'\]"),
    ({'points_m': [[0, 0, 0], [0.01, 0, 0]], 'frame': 'world'},
     "path.frame: 'world' is not one of"),
    ({'points_m': [[0, 0, 0], [0.01, 0]]}, r'path.points_m\[1\]: expected \[x, y, z\]'),
    ({'points_m': [[0, 0, 0], [0.01, 'a', 0]]}, r'path.points_m\[1\]: expected three numbers'),
    ({'points_m': 'duct.csv'}, 'path.points_m: expected a list'),
    ({'file': 3}, 'path.file: expected a file name'),
    ([[0, 0, 0]], 'path: expected a mapping'),
])
def test_bad_path_blocks_are_named(block, message):
    with pytest.raises(PlanInputError, match=f'scene.yaml: {message}'):
        paths.load_path(block, *BASE, '.', 'scene.yaml')


def test_inline_points_take_yaml_1_1_number_strings():
    path = paths.load_path({'points_m': [[0, 0, 0], ['1e-2', 0, 0]]}, *BASE)
    assert path.length_m == pytest.approx(0.01)


# Turns the model cannot take.

def test_a_path_must_turn_no_more_than_the_links_can_follow():
    # Two 70-degree turns 1 mm apart: each is fine alone, not both within two 10 mm links.
    turn = math.radians(70)
    points = [[0, 0, 0], [0.020, 0, 0], [0.020 + 0.001 * math.cos(turn),
                                         0.001 * math.sin(turn), 0]]
    points.append(np.array(points[-1]) + 0.020 * np.array([math.cos(2 * turn),
                                                           math.sin(2 * turn), 0]))
    path = Path(points, 'zigzag.csv')
    paths.check_followable(path, 0.0005)  # links shorter than the gap take one turn each
    with pytest.raises(PlanInputError, match=r'zigzag.csv: point [12]: the path turns 13\d.\d '
                                             r'degrees within two links \(10 mm each\) at '
                                             r'20.\d\d mm along it'):
        paths.check_followable(path, 0.010)


def test_an_arc_tighter_than_about_half_a_link_is_refused():
    link = 0.010
    limit = 3 * link / (2 * math.pi)
    for radius, fits in ((1.05 * limit, True), (0.95 * limit, False)):
        angle = np.linspace(0, 1.5 * math.pi, 1081)
        arc = radius * np.column_stack([np.sin(angle), 1 - np.cos(angle), 0 * angle])
        path = Path(np.vstack([[-0.02, 0, 0], arc]), 'arc.csv')
        if fits:
            paths.check_followable(path, link)
        else:
            with pytest.raises(PlanInputError, match=r'radius of curvature under 4.77 mm'):
                paths.check_followable(path, link)
