"""Study files: points as the file says, and every refusal naming its key."""

import pathlib

import numpy as np
import pytest
from tentacle_studies.study import load_study, StudyError

TENTACLE = pathlib.Path(__file__).resolve().parents[3] / 'config' / 'tentacles' / \
    'braided_chapter5.yaml'

GRID = """name: grid
field_t: [0.0, 0.005, 0.0]
vary:
  magnetisation_deg.3: {from: 0, to: 90, count: 4}
  field_t.y: [0.001, 0.002]
"""


def test_a_grid_is_every_combination_the_last_name_fastest(write_study):
    study = load_study(write_study(GRID))
    assert study.names == ['magnetisation_deg.3', 'field_t.y'] and study.size == 8
    points = study.points()
    assert points['magnetisation_deg.3'].tolist() == [0, 0, 30, 30, 60, 60, 90, 90]
    assert points['field_t.y'].tolist() == [0.001, 0.002] * 4
    part = study.points(3, 6)   # any slice is the same points
    assert part['magnetisation_deg.3'].tolist() == [30, 60, 60]
    assert study.dof == 3 and study.inserted_m == study.tentacle.length_m


@pytest.mark.parametrize('kind', ['latin_hypercube', 'random'])
def test_a_sample_draws_within_the_ranges_and_from_the_lists(write_study, kind):
    text = f"""name: drawn
vary:
  magnetisation_deg.4: {{from: -90, to: 90}}
  field_t.x: [0.0, 0.003, 0.006]
sample: {{{kind}: 200, seed: 7}}
"""
    study = load_study(write_study(text))
    points = study.points()
    angles = points['magnetisation_deg.4']
    assert study.size == 200 and np.all((angles >= -90) & (angles < 90))
    assert set(points['field_t.x'].tolist()) == {0.0, 0.003, 0.006}
    again = load_study(write_study(text, 'again.yaml')).points(50, 60)
    np.testing.assert_array_equal(again['magnetisation_deg.4'], angles[50:60])
    if kind == 'latin_hypercube':   # one point in each of the 200 strata of each range
        strata = np.floor((angles + 90) / 180 * 200).astype(int)
        assert sorted(strata.tolist()) == list(range(200))


@pytest.mark.parametrize('text, message', [
    ('name: x\nvary: {magnetisation_deg.9: [0]}\n', 'vary.magnetisation_deg.9: segment'),
    ('name: x\nvary: {stiffness.0: [0]}\n', 'vary.stiffness.0: unknown name'),
    ('name: x\nvary: {field_t.y: {from: 0, to: 1}}\n', 'a grid needs a count'),
    ('name: x\nvary: {field_t.y: []}\n', 'an empty list'),
    ('name: x\nvary: {field_t.y: [0]}\nsample: {sobol: 3}\n', 'sample'),
    ('name: x\nvary: {field_t.y: [0]}\nsample: {random: 0}\n', 'sample.random'),
    ('name: x\ncompute: plan\nvary: {field_t.y: [0]}\n', 'a plan study names its scene'),
    ('name: x\ncompute: trajectory\nvary: {field_t.y: [0]}\n', "'equilibrium' or 'plan'"),
    ('name: x\nvary: {seed: [0, 1]}\n', 'vary.seed: only a plan study (compute: plan) has a seed'),
    ('name: x\nvary: {field_t.y: [0]}\nmodel: {dof: 2}\n', 'model.dof'),
    ('name: x\nvary: {field_t.y: [0]}\nmodel: {start: cold}\n',
     "model.start: 'cold' is not 'previous' or 'straight'"),
    ('name: x\nvary: {field_t.y: [nan]}\n', 'vary.field_t.y[0]'),
    ('name: x\ninserted_m: 1.0\nvary: {field_t.y: [0]}\n', 'inserted_m: 1 m is more'),
    ('name: x\nvary: {field_t.y: {from: 0, to: 1, count: 100000}, '
     'field_t.x: {from: 0, to: 1, count: 1000}}\n', 'points: at most'),
    ('name: x\nvary: {field_t.y: {from: 0, to: 1, count: 1000000000000}}\n',
     'points: at most'),   # refused before any value is made
    ('name: x\nscene: s.yaml\nvary: {field_t.y: [0]}\n', 'and no scene'),
    ('name: x\nvary: {field_t.y: [0]}\nextra: 1\n', "unknown key(s) ['extra']"),
    ('name: x\npoints_of_interest_m: [0.06]\nvary: {field_t.y: [0]}\n',
     'points_of_interest_m[0]: 0.06 m is past the inserted'),
])
def test_a_bad_study_is_refused_naming_the_key(write_study, text, message):
    with pytest.raises(StudyError, match=None) as caught:
        load_study(write_study(text))
    assert message in str(caught.value), str(caught.value)


def test_a_passive_segment_cannot_be_turned(tmp_path):
    text = TENTACLE.read_text().replace(
        'magnetisation: {remanence_t: 0.12, direction: [-1.000000, 0.000000, 0.0]}',
        'magnetisation: none')
    (tmp_path / 'passive.yaml').write_text(text)
    path = tmp_path / 'study.yaml'
    path.write_text('name: x\ntentacle: passive.yaml\nvary: {magnetisation_deg.0: [0]}\n')
    with pytest.raises(StudyError, match='segment 0 is not magnetised'):
        load_study(path)


def test_a_bad_tentacle_file_is_refused_naming_the_study(tmp_path):
    path = tmp_path / 'study.yaml'
    path.write_text('name: x\ntentacle: missing.yaml\nvary: {field_t.y: [0]}\n')
    with pytest.raises(StudyError, match='tentacle'):
        load_study(path)
