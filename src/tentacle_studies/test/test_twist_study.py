"""A twist-stability study: reinforcement and the field's angle and strength varied (chapter 4)."""

import math
import pathlib

import numpy as np
import pyarrow.parquet as pq
import pytest
from tentacle_model import spatial
from tentacle_model.chain import discretise
from tentacle_model.statics import solve
from tentacle_model.tentacle_spec import load_tentacle, parse_tentacle
from tentacle_studies import sweep_cli
from tentacle_studies.equilibria import varied_tentacle
from tentacle_studies.study import load_study, StudyError
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]
CHAPTER4 = ROOT / 'config' / 'tentacles' / 'reinforced_chapter4.yaml'
STUDY = ROOT / 'config' / 'studies' / 'ch4_twist_stability.yaml'


def made(changes):
    """Return the chapter 4 tentacle as its file would be written with changes {segment: {...}}."""
    document = yaml.safe_load(CHAPTER4.read_text())
    for k, change in changes.items():
        document['segments'][k]['reinforcement'].update(change.get('reinforcement', {}))
        if 'youngs_modulus_pa' in change:
            document['segments'][k]['youngs_modulus_pa'] = change['youngs_modulus_pa']
    return parse_tentacle(document)


def same(a, b):
    """Return whether two tentacles' segments have the same stiffness and fibres."""
    return all(s.modulus_pa == pytest.approx(t.modulus_pa, rel=1e-12)
               and s.matrix_modulus_pa == t.matrix_modulus_pa
               and s.reinforcement == t.reinforcement for s, t in zip(a.segments, b.segments))


def test_fibre_names_make_the_tentacle_its_file_would():
    spec = load_tentacle(CHAPTER4)
    every = varied_tentacle(spec, {'fibre_modulus_pa': 1e7})
    assert same(every, made({k: {'reinforcement': {'fibre_modulus_pa': 1e7}} for k in (0, 2, 4)}))
    assert not same(every, spec)
    one = varied_tentacle(spec, {'fibre_angle_deg.2': 60.0, 'fibre_diameter_m.2': 3e-4,
                                 'youngs_modulus_pa.2': 2e5})
    assert same(one, made({2: {'reinforcement': {'angle_deg': 60.0, 'fibre_diameter_m': 3e-4},
                               'youngs_modulus_pa': 2e5}}))
    assert one.segments[0] is spec.segments[0]
    # a pseudo-modulus set outright is the segment's, whatever its fibres
    outright = varied_tentacle(spec, {'fibre_angle_deg.2': 60.0, 'twist_modulus_pa.2': 5e5})
    assert outright.segments[2].modulus_pa[2] == 5e5


def test_the_chapter4_map_is_the_3dof_stiffness_at_each_planar_shape(tmp_path, capsys):
    out = tmp_path / 'ch4'
    assert sweep_cli.main([str(STUDY), '--out', str(out), '--workers', '1']) == 0
    table = pq.read_table(out / 'results.parquet')
    assert table.column_names[-1] == 'twist_stability' and table.num_rows == 8 * 36 * 21
    assert (out / 'plot.png').read_bytes().startswith(b'\x89PNG')
    rows = {n: table.column(n).to_numpy() for n in table.column_names}
    assert rows['converged'].all()
    # points along one field direction ramp up from zero: check the last of some ramps
    rng = np.random.default_rng(4)
    for p in 21 * rng.choice(8 * 36, 6, replace=False) + 20:
        modulus, angle = rows['fibre_modulus_pa'][p], math.radians(rows['field_angle_deg'][p])
        field = rows['field_strength_t'][p] * np.array([math.cos(angle), math.sin(angle), 0.0])
        spec = made({k: {'reinforcement': {'fibre_modulus_pa': float(modulus)}}
                     for k in (0, 2, 4)})
        chain = discretise(spec, sublinks=4)
        state = None
        for scale in np.linspace(0.0, 1.0, 21):   # the study's ramp, from zero
            state = solve(chain, scale * field, dof=1, initial=state).angles_rad
        q = np.column_stack([np.diff(state, prepend=0.0), np.zeros((chain.size, 2))])
        hessian = spatial.evaluate(chain, q, field).hessian
        assert rows['twist_stability'][p] == pytest.approx(np.linalg.eigvalsh(hessian)[0],
                                                           rel=1e-6, abs=1e-12)
    # the unreinforced tentacle twists somewhere, PLA's (the prototype's) nowhere
    weakest = rows['fibre_modulus_pa'] == 1e5
    assert (rows['twist_stability'][weakest] < 0).any()
    assert (rows['twist_stability'][rows['fibre_modulus_pa'] == 2.4e9] > 0).all()
    least = min(m for m in np.unique(rows['fibre_modulus_pa'])
                if (rows['twist_stability'][rows['fibre_modulus_pa'] == m] > 0).all())
    assert f'stable at every field: {least:g}' in capsys.readouterr().out


@pytest.mark.parametrize('vary, model, message', [
    ('field_angle_deg: [0.0]', '', 'vary together'),
    ('field_angle_deg: [0.0]\n  field_strength_t: [0.01]\n  field_t.z: [0.0]', '',
     'vary together'),
    ('field_angle_deg: [0.0]\n  field_strength_t: [-0.01]', '', 'cannot be negative'),
    ('fibre_angle_deg.1: [60.0]', '', 'segment 1 has no reinforcement'),
    ('fibre_angle_deg: [95.0]', '', 'from 0 to 90 deg'),
    ('fibre_diameter_m.0: [0.002]', '', 'outside its section'),
    ('fibre_modulus_pa: [0.0]', '', 'must be above zero'),
    ('fibre_modulus_pa.9: [1.0e+9]', '', "segment '9'"),
    ('field_t.y: [0.01]', '\nmodel: {dof: 3, twist_stability: true}', "give 'dof: 1'"),
])
def test_a_twist_study_is_checked(tmp_path, vary, model, message):
    path = tmp_path / 'study.yaml'
    path.write_text(f'name: x\ntentacle: {CHAPTER4}{model}\nvary:\n  {vary}\n')
    with pytest.raises(StudyError) as caught:
        load_study(path)
    assert message in str(caught.value), str(caught.value)


def test_fibre_names_need_a_reinforced_tentacle(tmp_path):
    path = tmp_path / 'study.yaml'
    path.write_text(f'name: x\ntentacle: {ROOT / "config" / "tentacles" / "chapter2.yaml"}\n'
                    'vary:\n  fibre_modulus_pa: [1.0e+9]\n')
    with pytest.raises(StudyError, match='no reinforced segment'):
        load_study(path)


def test_the_field_angle_is_in_the_bases_plane(tmp_path):
    """A base turned about z: the field at 0 deg lies along its insertion direction."""
    document = yaml.safe_load((ROOT / 'config' / 'tentacles' / 'chapter2.yaml').read_text())
    document['base'] = {'direction': [0.0, 1.0, 0.0], 'normal': [-1.0, 0.0, 0.0]}
    (tmp_path / 't.yaml').write_text(yaml.safe_dump(document))
    (tmp_path / 's.yaml').write_text('name: x\ntentacle: t.yaml\nmodel: {dof: 1}\nvary:\n'
                                     '  field_angle_deg: [0.0, 90.0]\n'
                                     '  field_strength_t: [0.004]\n')
    from tentacle_studies.equilibria import _directions_and_fields
    study = load_study(tmp_path / 's.yaml')
    _, fields = _directions_and_fields(study, study.points(), study.size)
    np.testing.assert_allclose(fields, [[0.0, 0.004, 0.0], [-0.004, 0.0, 0.0]], atol=1e-18)
