"""Chapter 2's learned inverse: redundancy removal, the network, the forward check, direct."""

import pathlib

import numpy as np
import pytest
from sklearn.model_selection import train_test_split
from tentacle_studies import equilibria, inverse, inverse_cli, sweep_cli
from tentacle_studies.study import load_study

ROOT = pathlib.Path(__file__).resolve().parents[3]
CHAPTER2 = ROOT / 'config' / 'tentacles' / 'chapter2.yaml'
BABBLE = ROOT / 'config' / 'studies' / 'ch2_babble.yaml'
TWO_MAGNETS = """name: two
field_t: [0.0, 0.005, 0.0]
points_of_interest_m: [0.02, 0.03]
vary:
  magnetisation_deg.3: {from: 0, to: 330, count: 12}
  magnetisation_deg.4: {from: 0, to: 330, count: 12}
"""


def test_each_magnet_keeps_the_half_turn_on_which_its_deflection_rises():
    angles = np.arange(0.0, 360.0, 15.0)
    phase = np.array([0.0, 30.0, -45.0])
    t = np.radians(np.stack(np.meshgrid(angles, angles, angles, indexing='ij'), axis=-1))
    # a magnet's own deflection sin(angle - phase), plus its neighbour's, which averages out
    own = np.sin(t - np.radians(phase))
    deflections = own + 0.3 * np.sin(np.roll(t, 1, axis=-1))
    grid = inverse.Babble(('a', 'b', 'c'), (angles,) * 3, deflections)
    mask, arcs = inverse.redundancy_mask(grid)
    for k, p in enumerate(phase):   # least at phase - 90 deg, greatest at phase + 90 deg
        start = int(((p - 90.0) % 360.0) / 15.0)
        assert arcs[k] == [(start + i) % 24 for i in range(13)]
    assert mask.sum() == 13 ** 3
    kept_angles, kept = grid.points(mask)
    assert kept.shape == kept_angles.shape == (13 ** 3, 3)
    np.testing.assert_allclose(np.sin(kept_angles - np.radians(phase)) + 0.3 * np.sin(
        np.roll(kept_angles, 1, axis=-1)), kept, atol=1e-12)


def test_a_deflection_is_along_the_bases_normal_from_the_straight_body(tmp_path):
    study = _study(tmp_path, TWO_MAGNETS)
    rotation = study.tentacle.base_rotation
    offsets = np.array([[0.002, -0.001], [0.0, 0.0005]])   # (points, magnets), m
    columns = {}
    for k, s in enumerate(study.points_of_interest_m):
        at = (study.tentacle.base_position_m + s * rotation[:, 0] + offsets[:, k, None]
              * rotation[:, 1] + 0.003 * rotation[:, 2])   # out of plane: not a deflection
        columns.update({f'poi_{k}_{a}_m': at[:, i] for i, a in enumerate('xyz')})
    np.testing.assert_allclose(inverse.deflections(study, columns), offsets, atol=1e-15)


@pytest.mark.parametrize('change, message', [
    (('sample: grid', 'sample: {random: 10, seed: 1}'), 'a babble is a grid'),
    (('magnetisation_deg.4: {', 'field_t.y: {'), 'magnetisation_deg names only'),
    (('[0.02, 0.03]', '[0.02]'), '2 magnets varied but 1 points_of_interest_m'),
    (('to: 330, count: 12}\n', 'to: 345, count: 12}\n'), 'evenly through a whole turn'),
])
def test_a_study_that_is_not_a_babble_is_refused(tmp_path, change, message):
    study = _study(tmp_path, (TWO_MAGNETS + 'sample: grid\n').replace(*change))
    columns = equilibria.solve_points(study, 0, study.size)
    with pytest.raises(inverse.BabbleError, match=message):
        inverse.babble(study, columns)


def test_a_table_not_yet_whole_is_refused(tmp_path):
    study = _study(tmp_path, TWO_MAGNETS)
    with pytest.raises(inverse.BabbleError, match='holds 100 of 144 points'):
        inverse.babble(study, equilibria.solve_points(study, 0, 100))


def test_the_network_learns_a_known_inverse():
    rng = np.random.default_rng(0)
    angles = np.radians(rng.uniform(-60.0, 60.0, (500, 3)))

    def deflections_of(a):   # monotonic on the range, a coupling between the first two
        return 1e-3 * np.column_stack([np.sin(a[:, 0]), np.sin(a[:, 1]) + 0.2 * np.sin(
            a[:, 0]), np.sin(a[:, 2])])

    network = inverse.Inverse((16, 16)).fit(deflections_of(angles[:400]), angles[:400])
    got = network.angles_rad(deflections_of(angles[400:]))
    assert got.shape == (100, 3)
    assert np.degrees(np.abs(got - angles[400:])).mean() < 1.5


def test_the_forward_check_solves_each_answer_from_straight(tmp_path):
    study = _study(tmp_path, TWO_MAGNETS)
    angles = np.radians([[30.0, -20.0], [200.0, 170.0], [90.0, 90.0], [0.0, 0.0]])
    names = study.names
    got, stable = inverse.forward(study, names, angles)
    backwards, _ = inverse.forward(study, names, angles[::-1])
    np.testing.assert_array_equal(backwards[::-1], got)   # no answer steers the next
    columns = equilibria.solve_at(study, {n: np.degrees(angles[:, k])
                                          for k, n in enumerate(names)}, warm=False)
    np.testing.assert_array_equal(inverse.deflections(study, columns), got)
    assert got.shape == (4, 2) and stable.dtype == bool


def test_the_thesis_error_is_the_summed_error_over_the_summed_request():
    requested = np.array([[2.0, 6.0, 5.0], [1.0, 0.0, -5.0]])
    achieved = np.array([[2.5, 6.0, 4.0], [1.0, 0.5, -5.0]])
    assert inverse.deflection_error(achieved, requested) == pytest.approx(2.0 / 19.0)


def test_direct_finds_the_angles_that_made_a_shape():
    study = load_study(BABBLE)
    names = study.names
    made = np.radians([40.0, -30.0, 10.0])   # inside each magnet's rising half
    requested, _ = inverse.forward(study, names, made[None])
    found = inverse.direct(study, names, requested[0], made + np.radians([12.0, -10.0, 8.0]))
    np.testing.assert_allclose(found.deflections_m, requested[0], rtol=0, atol=1e-8)
    np.testing.assert_allclose(np.degrees(found.angles_rad), np.degrees(made), atol=1e-3)
    assert found.stable and found.solves >= 4


def test_the_thesis_network_on_the_chapter2_babble_beats_its_error():
    study = load_study(BABBLE)
    grid = inverse.babble(study, equilibria.solve_points(study, 0, study.size))
    mask, _ = inverse.redundancy_mask(grid)
    angles, deflections = grid.points(mask)
    a_train, a_test, d_train, d_test = train_test_split(angles, deflections, test_size=0.15,
                                                        random_state=0)
    network = inverse.Inverse().fit(d_train, a_train)
    achieved, stable = inverse.forward(study, grid.names, network.angles_rad(d_test))
    assert stable.all()
    assert inverse.deflection_error(achieved, d_test) < 0.063   # the thesis' 6.3%


def _study(tmp_path, text):
    path = tmp_path / 'study.yaml'
    path.write_text(f'tentacle: {ROOT / "config" / "tentacles" / "braided_chapter5.yaml"}\n'
                    + text)
    return load_study(path)


def test_tentacle_inverse_answers_shapes_checked_in_the_forward_model(tmp_path, capsys):
    made = np.radians([[40.0, -30.0, 10.0]])
    want_mm = 1e3 * inverse.forward(load_study(BABBLE), ('magnetisation_deg.1',
                                    'magnetisation_deg.3', 'magnetisation_deg.5'), made)[0][0]
    assert sweep_cli.main([str(BABBLE), '--out', str(tmp_path / 'ch2'), '--workers', '1']) == 0
    capsys.readouterr()
    for table in (['--table', str(tmp_path / 'ch2')], []):   # read, or solved here
        assert inverse_cli.main([str(BABBLE), *table, '--deflections-mm',
                                 *map(str, want_mm), '--deflections-mm', '2', '6', '5']) == 0
        lines = capsys.readouterr().out.splitlines()
        shape = '[' + ' '.join(f'{d:.2f}' for d in want_mm) + '] mm'
        assert lines[1].startswith(f'  requested {shape} -> magnetisation_deg.1 ')
        assert lines[1].endswith(f'achieved {shape}: error 0.0%')   # angles: one of several
        assert lines[2].endswith('(out of reach: the nearest shape found)')   # thesis' A
    assert inverse_cli.main([str(BABBLE), '--method', 'lookup', '--deflections-mm', '-1.0',
                             '-2.02', '0.79']) == 0
    assert ('magnetisation_deg.1 240.0, magnetisation_deg.3 180.0, magnetisation_deg.5 '
            '135.0 deg') in capsys.readouterr().out


@pytest.mark.parametrize('argv, message', [
    (['--deflections-mm', '2', '6'], 'one deflection a point of interest, 3 of them'),
    (['--deflections-mm', '0', '0', '0'], 'not all zero'),
    (['--deflections-mm', '1', 'nan', '0'], 'finite'),
    (['--table', '{tmp}', '--deflections-mm', '1', '2', '3'], 'no results table'),
    (['--table', '{two}', '--deflections-mm', '1', '2', '3'], 'another study'),
])
def test_tentacle_inverse_refuses_bad_input_naming_it(tmp_path, capsys, argv, message):
    assert sweep_cli.main([str(_study(tmp_path, TWO_MAGNETS).source), '--out',
                           str(tmp_path / 'two'), '--workers', '1']) == 0
    argv = [a.format(tmp=tmp_path, two=tmp_path / 'two') for a in argv]
    assert inverse_cli.main([str(BABBLE), *argv]) == 2
    assert message in capsys.readouterr().err
