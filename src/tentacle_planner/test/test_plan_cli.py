"""tentacle-plan end to end on a scene written here: schedule file, picture, exit codes."""

import hashlib
import pathlib

import numpy as np
import pytest
from tentacle_planner import plan_cli
from tentacle_planner.optimise import Constraints, optimise, Problem
from tentacle_planner.paths import shape_error
from tentacle_planner.planner import plan_scene
from tentacle_planner.scene import load_scene
from tentacle_planner.schedule_file import FORMAT
from tentacle_planner.schedule_writer import schedule_document
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]
BRAIDED = ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml'


def arc_scene(tmp_path, dof=1, radius_m=0.06, **extra):
    """Write a scene: the braided tentacle along an in-plane arc; return its path."""
    s = np.linspace(0.0, 0.06, 61)
    points = np.column_stack([radius_m * np.sin(s / radius_m),
                              radius_m * (1 - np.cos(s / radius_m)), 0 * s])
    document = {'name': 'arc', 'tentacle': str(BRAIDED),
                'path': {'points_m': points.round(9).tolist()},
                'insertion_steps_m': [0.03, 0.04, 0.05],
                'coil': {'max_field_t': 0.02}, 'model': {'dof': dof, 'sublinks': 1},
                'magnetisation': {'planar': dof == 1}, **extra}
    path = tmp_path / 'arc.yaml'
    path.write_text(yaml.safe_dump(document))
    return path


def test_a_scene_is_planned_written_and_verified(tmp_path, capsys):
    scene_file = arc_scene(tmp_path, playback_step_m=0.005)
    out = tmp_path / 'out'
    code = plan_cli.main(['--scene', str(scene_file), '--out', str(out), '--starts', '3'])
    printed = capsys.readouterr()
    assert code == 0, printed.out + printed.err
    schedule = yaml.safe_load((out / 'schedule.yaml').read_text())
    assert schedule['format'] == FORMAT and schedule['flags'] == []
    assert schedule['scene']['sha256'] == hashlib.sha256(scene_file.read_bytes()).hexdigest()
    assert [s['insertion_m'] for s in schedule['steps']] == pytest.approx(
        [0.005 * k for k in range(1, 11)])
    assert [s['insertion_m'] for s in schedule['steps'] if s['key']] == pytest.approx(
        [0.03, 0.04, 0.05])
    scene = load_scene(scene_file)
    for step in schedule['steps']:
        assert max(abs(b) for b in step['field_t']) <= 0.02 + 1e-12
        assert step['stability'] > 0
        rms, tip = shape_error(np.array(step['predicted_centreline_m']), scene.path,
                               step['insertion_m'])
        assert step['shape_rms_m'] == pytest.approx(rms, abs=1e-9)
        if step['key']:
            assert rms < 0.05 * scene.tentacle.length_m
    directions = [seg['magnetisation']['direction'] for seg in schedule['tentacle']['segments']
                  if seg.get('magnetisation')]
    assert all(np.linalg.norm(d) == pytest.approx(1.0) for d in directions)
    assert len(schedule['magnetisation_deg']) == len(directions)
    assert [row['model'] for row in schedule['robustness']['nominal_plan']][0] == 'nominal'
    assert (out / 'plan.png').stat().st_size > 10_000
    assert 'shape RMS' in printed.out and 'no flags' in printed.out


def channel_walls(radius_m, half_width_m):
    """Return the scene's walls: either side of arc_scene's arc, 0.25 mm apart, in its plane."""
    s = np.arange(0.0, 0.06, 2.5e-4)
    return {'walls': [{'points_m': np.column_stack([
        (radius_m - side) * np.sin(s / radius_m),
        radius_m - (radius_m - side) * np.cos(s / radius_m), 0 * s]).round(9).tolist()}
        for side in (half_width_m, -half_width_m)]}


def test_a_channel_narrower_than_the_body_is_flagged_with_the_least_penetration(
        tmp_path, capsys):
    # A 2 mm body in a straight 1.8 mm channel: no plan keeps off; the least it can go into
    # a wall, straight and centred, is 0.1 mm (to the walls' points 0.25 mm apart, at least
    # 0.0914 mm).
    straight = 1e3   # m: the arc's radius
    scene_file = arc_scene(tmp_path, radius_m=straight,
                           obstacles=channel_walls(straight, 0.0009))
    code = plan_cli.main(['--scene', str(scene_file), '--out', str(tmp_path / 'out'),
                          '--starts', '2'])
    printed = capsys.readouterr()
    assert code == 3, printed.out + printed.err
    flags = yaml.safe_load((tmp_path / 'out' / 'schedule.yaml').read_text())['flags']
    least = [f for f in flags if f.startswith('no plan found keeps the body off')]
    assert len(least) == 1 and least == flags[:1], flags
    depth_mm = float(least[0].split('least penetration found is ')[1].split(' mm')[0])
    assert 0.09 <= depth_mm <= 0.11
    assert any(f.startswith('the body touches wall') for f in flags[1:])
    # A channel on the arc, 2.6 mm wide (the papilla's): the plan keeps off, unflagged.
    wide = arc_scene(tmp_path, obstacles=channel_walls(0.06, 0.0013))
    assert plan_cli.main(['--scene', str(wide), '--out', str(tmp_path / 'wide'),
                          '--starts', '2']) == 0, capsys.readouterr().err


def test_the_same_seed_writes_the_same_schedule(tmp_path):
    scene = load_scene(arc_scene(tmp_path))
    first = schedule_document(plan_scene(scene, seed=4, starts=2))
    assert schedule_document(plan_scene(scene, seed=4, starts=2)) == first


def test_bad_input_is_named_and_exits_2(tmp_path, capsys):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('name: x\ntentacle: nowhere.yaml\npath: {points_m: [[0, 0, 0]]}\n'
                   'insertion_steps_m: [0.01]\n')
    assert plan_cli.main(['--scene', str(bad), '--out', str(tmp_path / 'o')]) == 2
    assert 'bad.yaml' in capsys.readouterr().err
    assert not (tmp_path / 'o').exists()


def test_a_tentacle_and_a_path_file_plan_as_the_same_scene_would(tmp_path, capsys):
    scene_file = arc_scene(tmp_path)
    scene = load_scene(scene_file)
    csv = tmp_path / 'arc.csv'    # the same path in mm, as a lab exports it
    np.savetxt(csv, scene.path.points_m * 1e3, delimiter=',', header='x_mm,y_mm,z_mm',
               comments='')
    out = tmp_path / 'out'
    code = plan_cli.main(['--tentacle', str(BRAIDED), '--path', str(csv), '--out', str(out),
                          '--steps', '0.03,0.04,0.05', '--max-field', '0.02', '--dof', '1',
                          '--planar-magnetisation', '--starts', '1', '--iterations', '30'])
    printed = capsys.readouterr()
    assert code == 0, printed.out + printed.err
    from_files = yaml.safe_load((out / 'schedule.yaml').read_text())
    from_scene = schedule_document(plan_scene(scene, starts=1, iterations=30))
    np.testing.assert_allclose([s['field_t'] for s in from_files['steps']],
                               [s['field_t'] for s in from_scene['steps']], atol=1e-9)
    assert from_files['scene']['name'] == 'arc'
    # Without --steps: a key step at every segment end the path is long enough for.
    assert plan_scene_steps(csv) == pytest.approx([0.01, 0.02, 0.03, 0.04, 0.05])


def plan_scene_steps(path_file):
    from tentacle_planner.scene import scene_of
    return list(scene_of(BRAIDED, path_file).insertion_steps_m)


@pytest.mark.parametrize('args, message', [
    (['--tentacle', str(BRAIDED)], 'give --scene FILE, or --tentacle FILE and --path FILE'),
    (['--scene', 'x.yaml', '--path', 'p.csv'], '--scene takes every setting'),
    (['--tentacle', str(BRAIDED), '--path', 'p.csv', '--steps', '0.01,x'], 'commas'),
])
def test_conflicting_or_missing_options_are_refused(tmp_path, capsys, args, message):
    with pytest.raises(SystemExit) as exit_:
        plan_cli.main(args + ['--out', str(tmp_path / 'o')])
    assert exit_.value.code == 2 and message in capsys.readouterr().err


def test_a_missing_path_file_is_named(tmp_path, capsys):
    missing = tmp_path / 'nowhere.csv'
    assert plan_cli.main(['--tentacle', str(BRAIDED), '--path', str(missing),
                          '--out', str(tmp_path / 'o')]) == 2
    assert 'nowhere.csv' in capsys.readouterr().err


def test_ctrl_c_keeps_the_best_plan_so_far(tmp_path):
    scene = load_scene(arc_scene(tmp_path))
    from tentacle_planner.planner import problem_of

    class Interrupted(Problem):
        calls = 0

        def residuals(self, x, jacobian=True):
            Interrupted.calls += 1
            if Interrupted.calls == 60:  # somewhere in the second start
                raise KeyboardInterrupt
            return super().residuals(x, jacobian)

    base = problem_of(scene)
    problem = Interrupted(base.model, base.steps_m, base.targets, base.constraints)
    plan = optimise(problem, seed=0, starts=4)
    assert plan.interrupted and plan.flags[-1] == 'interrupted: the best plan so far'
    assert len(plan.steps) == 3 and np.all(np.isfinite(plan.fields_t))
    assert isinstance(problem.constraints, Constraints)
