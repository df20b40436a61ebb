"""tentacle-sweep: each row the model's equilibrium; chunks kept on Ctrl-C, resumed once."""

import pathlib

import numpy as np
import pyarrow.parquet as pq
import pytest
from tentacle_model.model import TentacleModel
from tentacle_model.tentacle_spec import load_tentacle
from tentacle_studies import engines, equilibria, sweep_cli
from tentacle_studies.study import load_study, StudyError
import yaml

STUDY = """name: two_magnets
field_t: [0.0, 0.005, 0.0]
model: {dof: 3, sublinks: 1, gravity_m_s2: [0.0, 0.0, -9.81]}
vary:
  magnetisation_deg.3: {from: 0, to: 330, count: 12}
  magnetisation_deg.4: {from: 0, to: 330, count: 12}
"""
ROOT = pathlib.Path(__file__).resolve().parents[3]
COLUMNS = ['magnetisation_deg.3', 'magnetisation_deg.4', 'tip_x_m', 'tip_y_m', 'tip_z_m',
           'converged', 'stable', 'stability']


def test_every_row_is_the_models_equilibrium_from_the_row_before(write_study, tmp_path):
    path = write_study(STUDY)
    assert sweep_cli.main([str(path), '--out', str(tmp_path / 'out'), '--chunk', '50',
                           '--csv', '--workers', '1']) == 0
    table = pq.read_table(tmp_path / 'out' / 'results.parquet')
    assert table.column_names == COLUMNS and table.num_rows == 144
    assert (tmp_path / 'out' / 'results.csv').read_text().count('\n') == 145
    assert (tmp_path / 'out' / 'plot.png').read_bytes().startswith(b'\x89PNG')
    study = load_study(path)
    model = TentacleModel(study.tentacle, dof=3, gravity_m_s2=study.gravity_m_s2)
    chain = model.chain(study.inserted_m)
    magnitudes = np.linalg.norm(chain.moments_a_m2, axis=1)
    rows = table.to_pydict()
    state = None
    for p in range(144):
        if p % 50 == 0:
            state = None   # a chunk's first point starts straight
        directions = np.array([s.magnetisation_a_per_m / max(np.linalg.norm(
            s.magnetisation_a_per_m), 1e-300) for s in study.tentacle.segments])
        for segment in (3, 4):
            angle = np.radians(rows[f'magnetisation_deg.{segment}'][p])
            directions[segment] = [np.cos(angle), np.sin(angle), 0.0]
        solution = model.solve(study.inserted_m, study.field_t, state,
                               magnitudes[:, None] * directions[chain.segment_index])
        eq = solution.equilibrium
        tip = [rows[f'tip_{axis}_m'][p] for axis in 'xyz']
        np.testing.assert_allclose(tip, eq.points_m[-1], rtol=0, atol=1e-12)
        assert rows['converged'][p] == eq.converged
        assert rows['stable'][p] == (eq.converged and eq.stability > 0)
        state = solution.state
    assert all(rows['converged'])
    assert np.ptp(rows['tip_y_m']) > 0.1 * study.tentacle.length_m


def test_ctrl_c_keeps_the_chunks_done_and_resume_computes_the_rest(
        write_study, tmp_path, monkeypatch, capsys):
    path, out = write_study(STUDY), tmp_path / 'out'
    solve, calls = engines.solve_points, []

    def interrupted(study, start, stop):
        calls.append((start, stop))
        if len(calls) == 2:
            raise KeyboardInterrupt
        return solve(study, start, stop)
    monkeypatch.setattr(engines, 'solve_points', interrupted)
    here = ['--chunk', '40', '--workers', '1']
    assert sweep_cli.main([str(path), '--out', str(out), *here]) == 130
    assert '40 of 144 points' in capsys.readouterr().err
    assert pq.read_table(out / 'results.parquet').num_rows == 40   # the first chunk, whole
    assert sweep_cli.main([str(path), '--out', str(out), *here]) == 2  # no --resume
    calls.clear()
    monkeypatch.setattr(engines, 'solve_points', lambda *a: calls.append(a[1:]) or solve(*a))
    assert sweep_cli.main([str(path), '--out', str(out), *here, '--resume']) == 0
    assert calls == [(40, 80), (80, 120), (120, 144)]   # only what was missing
    resumed = pq.read_table(out / 'results.parquet')
    assert sweep_cli.main([str(path), '--out', str(tmp_path / 'whole'), *here]) == 0
    assert resumed.equals(pq.read_table(tmp_path / 'whole' / 'results.parquet'))


@pytest.mark.parametrize('vary, drawn', [
    ('  field_t.y: {from: -0.01, to: 0.01, count: 9}\n', True),
    ('  field_t.x: [0.0, 0.001]\n  field_t.y: [0.0, 0.002]\n  field_t.z: [0.0, 0.003]\n',
     False)])
def test_a_plot_for_one_or_two_varied_names(write_study, tmp_path, vary, drawn):
    path = write_study(f'name: plotted\nvary:\n{vary}')
    assert sweep_cli.main([str(path), '--out', str(tmp_path / 'out')]) == 0
    assert (tmp_path / 'out' / 'plot.png').exists() == drawn


def test_resume_refuses_another_studys_table(write_study, tmp_path, capsys):
    out = tmp_path / 'out'
    assert sweep_cli.main([str(write_study(STUDY)), '--out', str(out)]) == 0
    other = write_study(STUDY.replace('count: 12', 'count: 6'), 'other.yaml')
    assert sweep_cli.main([str(other), '--out', str(out), '--resume']) == 2
    assert 'another study' in capsys.readouterr().err
    assert pq.read_table(out / 'results.parquet').num_rows == 144   # untouched


@pytest.mark.parametrize('argv, message', [
    (['--chunk', '0', '--out', 'o'], '--chunk and --workers must be'),
    (['--workers', '0', '--out', 'o'], '--chunk and --workers must be'),
    (['--out', '/dev/null/x'], 'cannot write results in /dev/null/x')])
def test_bad_arguments_exit_2(write_study, capsys, argv, message):
    assert sweep_cli.main([str(write_study(STUDY))] + argv) == 2
    assert message in capsys.readouterr().err


def test_local_workers_and_a_real_cluster_give_the_same_table(write_study, tmp_path):
    path = write_study(STUDY)
    tables = {}
    for name, argv in (('here', ['--workers', '1']), ('local', ['--workers', '2'])):
        assert sweep_cli.main([str(path), '--out', str(tmp_path / name), '--chunk', '30',
                               *argv]) == 0
        tables[name] = pq.read_table(tmp_path / name / 'results.parquet')
    with engines.cluster_processes(tmp_path, workers=2) as address:
        assert sweep_cli.main([str(path), '--out', str(tmp_path / 'cluster'), '--chunk', '30',
                               '--scheduler', address]) == 0
    tables['cluster'] = pq.read_table(tmp_path / 'cluster' / 'results.parquet')
    assert tables['here'].num_rows == 144
    assert tables['local'].equals(tables['here']) and tables['cluster'].equals(tables['here'])


def test_points_of_interest_lie_on_the_body(write_study, tmp_path):
    # At the base, at the tip, and half way along a link: on the segment between its joints.
    text = STUDY.replace('vary:', 'points_of_interest_m: [0.0, 0.0175, 0.05]\nvary:')
    path = write_study(text)
    assert sweep_cli.main([str(path), '--out', str(tmp_path / 'out')]) == 0
    rows = pq.read_table(tmp_path / 'out' / 'results.parquet').to_pydict()
    study = load_study(path)
    assert list(rows)[-9:] == [f'poi_{k}_{axis}_m' for k in range(3) for axis in 'xyz']
    base, tip = study.tentacle.base_position_m, np.column_stack(
        [rows[f'tip_{axis}_m'] for axis in 'xyz'])
    poi = [np.column_stack([rows[f'poi_{k}_{axis}_m'] for axis in 'xyz']) for k in range(3)]
    np.testing.assert_allclose(poi[0], np.broadcast_to(base, poi[0].shape), atol=1e-15)
    np.testing.assert_allclose(poi[2], tip, atol=1e-15)
    # 17.5 mm: half way along the second 10 mm segment's link (one sub-link a segment)
    lengths = [s.length_m for s in study.tentacle.segments]
    assert np.cumsum(lengths)[0] < 0.0175 < np.cumsum(lengths)[1]
    distance = np.linalg.norm(poi[1] - poi[0], axis=1)
    assert np.all(distance <= 0.0175 + 1e-12) and np.all(distance > 0.01)


STRUCTURAL_STUDY = """name: structure
field_t: [0.0, 0.006, 0.004]
model: {dof: 3, sublinks: 2}
vary:
  twist_modulus_pa.4: [1.0e+5, 1.0e+7]
  bend_modulus_pa.1: [2.0e+5, 5.0e+5]
  remanence_t.3: [0.05, 0.12]
  length_m.2: [0.008, 0.013]
  inserted_m: [0.035, 0.048]
"""


def test_structural_names_make_the_tentacle_a_file_would(write_study, tmp_path):
    study = load_study(write_study(STRUCTURAL_STUDY))
    rows = equilibria.solve_points(study, 0, study.size)
    assert study.size == 32 and rows['converged'].all()
    base = yaml.safe_load((ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml').read_text())
    for p in range(study.size):   # each point a tentacle of its own: from straight
        document = yaml.safe_load(yaml.safe_dump(base))
        segments = document['segments']
        segments[4]['youngs_modulus_pa']['twist'] = float(rows['twist_modulus_pa.4'][p])
        segments[1]['youngs_modulus_pa']['bend_1'] = float(rows['bend_modulus_pa.1'][p])
        segments[1]['youngs_modulus_pa']['bend_2'] = float(rows['bend_modulus_pa.1'][p])
        segments[3]['magnetisation']['remanence_t'] = float(rows['remanence_t.3'][p])
        segments[2]['length_m'] = float(rows['length_m.2'][p])
        path = tmp_path / 'made.yaml'
        path.write_text(yaml.safe_dump(document))
        model = TentacleModel(load_tentacle(path), dof=3, sublinks=2)
        eq = model.solve(float(rows['inserted_m'][p]), study.field_t).equilibrium
        np.testing.assert_allclose([rows[f'tip_{a}_m'][p] for a in 'xyz'], eq.points_m[-1],
                                   rtol=0, atol=1e-12)
        assert rows['stability'][p] == pytest.approx(eq.stability, rel=1e-9, abs=1e-15)
    tips = np.column_stack([rows['tip_x_m'], rows['tip_y_m']])
    assert np.ptp(tips, axis=0).max() > 0.01   # the names change the tentacle


@pytest.mark.parametrize('vary, message', [
    ('remanence_t.0: [0.1]', None),
    ('youngs_modulus_pa.0: [0.0, 1.0e+5]', 'youngs_modulus_pa must be above zero'),
    ('length_m.7: [0.01]', "segment '7'"),
    ('inserted_m: [0.06]', '0.06 m is more than the tentacle (0.05 m at its shortest)'),
    ('length_m.0: [0.002, 0.01]\n  inserted_m: [0.045]', 'at its shortest'),
    ('backbone_m: [0.01]', 'the tentacle has no backbone'),
    ('remanence_t.2: [-0.1]', 'remanence_t cannot be negative'),
    ('inserted_m.2: [0.01]', 'unknown name'),
])
def test_structural_names_are_checked_against_the_tentacle(write_study, vary, message):
    path = write_study(f'name: x\nvary:\n  {vary}\n')
    if message is None:
        assert load_study(path).names == [vary.split(':')[0]]
        return
    with pytest.raises(StudyError) as caught:
        load_study(path)
    assert message in str(caught.value), str(caught.value)


def test_a_backbone_reach_is_the_models(tmp_path):
    path = tmp_path / 'backbone.yaml'
    path.write_text(f'name: reach\ntentacle: {ROOT / "config" / "tentacles" / "vsr_chapter6.yaml"}'
                    '\nfield_t: [0.0, 0.015, 0.0]\nmodel: {dof: 1, sublinks: 2}\n'
                    'vary:\n  backbone_m: [0.0, 0.02, 0.04]\n')
    study = load_study(path)
    rows = equilibria.solve_points(study, 0, study.size)
    for p, reach in enumerate(rows['backbone_m']):
        model = TentacleModel(study.tentacle, dof=1, sublinks=2, backbone_m=reach)
        eq = model.solve(study.tentacle.length_m, study.field_t).equilibrium
        np.testing.assert_allclose(rows['tip_x_m'][p], eq.points_m[-1][0], rtol=0, atol=1e-12)
    assert rows['tip_x_m'][0] != rows['tip_x_m'][2]   # the backbone stiffens the base


PLAN_STUDY = """name: plans
compute: plan
scene: {scene}
vary:
  remanence_t.0: [0.04, 0.0535]
  seed: [0, 1]
"""


def test_a_plan_study_plans_each_point_as_the_planner_does(tmp_path):
    from dataclasses import replace
    from tentacle_planner.planner import plan_scene, shape_rms
    from tentacle_planner.scene import load_scene
    study_file = tmp_path / 'plans.yaml'
    study_file.write_text(PLAN_STUDY.format(scene=ROOT / 'config' / 'scenes' / 'ch3_a.yaml'))
    assert sweep_cli.main([str(study_file), '--out', str(tmp_path / 'out'), '--workers', '1',
                           '--csv']) == 0
    rows = pq.read_table(tmp_path / 'out' / 'results.parquet').to_pydict()
    assert list(rows) == ['remanence_t.0', 'seed', 'shape_rms_m', 'recheck_rms_m', 'flags']
    scene = load_scene(ROOT / 'config' / 'scenes' / 'ch3_a.yaml')
    document = yaml.safe_load(scene.tentacle_file.read_text())
    for p in range(4):
        document['segments'][0]['magnetisation']['remanence_t'] = rows['remanence_t.0'][p]
        path = tmp_path / 'tentacle.yaml'
        path.write_text(yaml.safe_dump(document))
        made = replace(scene, tentacle=load_tentacle(path), playback_step_m=None)
        result = plan_scene(made, seed=int(rows['seed'][p]), workers=1)
        assert rows['shape_rms_m'][p] == pytest.approx(shape_rms(made, result.plan.steps),
                                                       rel=1e-9)
        finer = [rms for what, rms in result.verification if what.startswith('higher')]
        assert rows['recheck_rms_m'][p] == pytest.approx(finer[0], rel=1e-9)
        assert rows['flags'][p] == '; '.join(result.flags)
    assert (tmp_path / 'out' / 'plot.png').exists()


@pytest.mark.parametrize('text, message', [
    ('vary: {field_t.y: [0.0]}', 'a plan study varies youngs_modulus_pa.K'),
    ('field_t: [0, 0, 0]\nvary: {seed: [0]}', 'field_t: a plan study takes it from its scene'),
    ('vary: {seed: [0.5]}', 'seeds are a list of whole numbers'),
    ('vary: {seed: {from: 0, to: 3, count: 4}}', 'seeds are a list of whole numbers'),
])
def test_a_plan_study_is_checked(tmp_path, text, message):
    path = tmp_path / 'plans.yaml'
    path.write_text(f'name: p\ncompute: plan\nscene: {ROOT / "config" / "scenes" / "ch3_a.yaml"}'
                    f'\n{text}\n')
    with pytest.raises(StudyError) as caught:
        load_study(path)
    assert message in str(caught.value), str(caught.value)
