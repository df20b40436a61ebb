"""Forward statics against closed forms and an independent boundary-value solution."""

from dataclasses import replace
import json
import pathlib
import time

import numpy as np
import pytest
from tentacle_model import planar
from tentacle_model.chain import discretise
from tentacle_model.elastica import cantilever_tip as elastica_tip
from tentacle_model.statics import compile_kernels, solve, solve_planar


def field(magnitude_t, degrees):
    phi = np.radians(degrees)
    return magnitude_t * np.array([np.cos(phi), np.sin(phi), 0.0])


def test_small_deflection_matches_thesis_eq_2_3(cantilever):
    spec, length, ei, ma = cantilever
    b_t = 2e-5  # small load: delta/L about 1%
    eq = solve_planar(discretise(spec, sublinks=100), field(b_t, 90))
    d = 0.002
    m = ma / (np.pi * d * d / 4)
    expected = 16 * m * b_t * length ** 2 / (3 * 1.0e5 * d * d)  # delta / L
    assert eq.converged
    assert eq.tip_m[1] / length == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize('degrees', [90, 135, 180])
def test_large_deflection_matches_the_elastica_at_second_order(cantilever, degrees):
    spec, length, ei, ma = cantilever
    b_t = 5e-3
    assert ma * b_t * length ** 2 / ei > np.pi ** 2 / 4  # above the buckling load at 180 deg
    reference = elastica_tip(length, ei, ma, b_t, degrees)
    errors = []
    sublinks = (8, 16, 32, 64)
    for n in sublinks:
        eq = solve_planar(discretise(spec, sublinks=n), field(b_t, degrees))
        assert eq.converged, eq.reason
        assert eq.stability > 0
        tip = eq.tip_m[:2] * ([1, -1] if eq.tip_m[1] * reference[1] < 0 else [1, 1])
        errors.append(np.linalg.norm(tip - reference) / length)
    assert errors[-1] < 0.005
    rates = np.diff(np.log(errors)) / np.log(0.5)
    assert np.all(rates > 1.9), rates  # the midpoint scheme is second order


def test_straight_rod_antiparallel_to_the_field_is_flagged_unstable(cantilever):
    spec, length, ei, ma = cantilever
    chain = discretise(spec, sublinks=20)
    a, b = planar.loads(chain, field(5e-3, 180))
    hess = planar.hessian_dense(np.zeros(20), chain.stiffness_n_m[:, 0], a, b)
    assert np.linalg.eigvalsh(hess)[0] < 0  # the straight state is a saddle
    eq = solve_planar(chain, field(5e-3, 180))
    assert 'saddle' in eq.reason and abs(eq.tip_m[1]) > 0.005 and eq.stability > 0


def test_below_the_buckling_load_antiparallel_stays_straight_and_stable(cantilever):
    spec, length, ei, ma = cantilever
    b_t = 0.5 * (np.pi ** 2 / 4) * ei / (ma * length ** 2)
    eq = solve_planar(discretise(spec, sublinks=20), field(b_t, 180))
    assert eq.converged and eq.stability > 0 and abs(eq.tip_m[1]) < 1e-12


@pytest.mark.parametrize('b_t', [0.0, 0.1])
def test_zero_and_strong_fields(cantilever, b_t):
    spec = cantilever[0]
    eq = solve_planar(discretise(spec, sublinks=30), field(b_t, 120))
    assert eq.converged and np.all(np.isfinite(eq.points_m))
    if b_t == 0:
        np.testing.assert_allclose(eq.tip_m, [0.02, 0, 0], atol=1e-15)
    else:  # beta about 136: the rod aligns its magnetisation with the field
        heading = eq.heading
        assert heading @ field(1.0, 120) > 0.99


def test_nothing_inserted_and_partial_links(cantilever):
    spec = cantilever[0]
    empty = solve_planar(discretise(spec, inserted_m=0.0), field(5e-3, 90))
    assert empty.converged and empty.reason == 'nothing inserted'
    np.testing.assert_allclose(empty.tip_m, [0, 0, 0])
    previous = None
    for inserted in np.linspace(0.001, 0.02, 7):
        chain = discretise(spec, inserted_m=inserted, sublinks=8)
        eq = solve_planar(chain, field(5e-3, 90))
        assert eq.converged
        assert np.sum(chain.lengths_m) == pytest.approx(inserted)
        if previous is not None:
            assert eq.tip_m[1] > previous  # more rod out, more deflection
        previous = eq.tip_m[1]


def test_thousand_links_in_bounded_time(cantilever):
    spec = cantilever[0]
    compile_kernels()  # once per process, seconds on a fresh machine: not this test's time
    t0 = time.monotonic()
    eq = solve_planar(discretise(spec, sublinks=1000), field(20e-3, 150))
    assert eq.converged, eq.reason
    assert time.monotonic() - t0 < 5.0


def test_bad_inputs_raise(cantilever):
    chain = discretise(cantilever[0], sublinks=4)
    with pytest.raises(ValueError, match='finite'):
        solve_planar(chain, [np.nan, 0, 0])
    with pytest.raises(ValueError, match='shape'):
        solve_planar(chain, [0.001, 0, 0], initial=np.zeros(3))


def test_command_line_json(capsys):
    from tentacle_model.statics_cli import main
    path = pathlib.Path(__file__).resolve().parents[3] / 'config/tentacles/cantilever.yaml'
    code = main(['--tentacle', str(path), '--field', '0', '0.005',
                 '0', '--sublinks', '64', '--json'])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out['converged'] is True and out['stability'] > 0
    np.testing.assert_allclose(out['tip'], [0.010675, 0.015271, 0.0], atol=3e-6)  # NOTES.md
    assert main(['--tentacle', 'nope.yaml', '--field', '0', '0', '0']) == 2
    assert 'nope.yaml' in capsys.readouterr().err


def test_command_line_three_dof_out_of_plane(capsys):
    from tentacle_model.statics_cli import main
    path = pathlib.Path(__file__).resolve().parents[3] / 'config/tentacles/cantilever.yaml'
    assert main(['--tentacle', str(path), '--field', '0', '0', '0.005', '--dof', '3',
                 '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['converged'] and out['tip'][2] > 0.01 and abs(out['tip'][1]) < 1e-12


def test_command_line_knobs(capsys):
    from tentacle_model.statics_cli import main
    tentacles = pathlib.Path(__file__).resolve().parents[3] / 'config/tentacles'

    def run(name, *args):
        code = main(['--tentacle', str(tentacles / name), '--sublinks', '2', '--json', *args])
        out = json.loads(capsys.readouterr().out)
        assert code == 0 and out['converged'], out['reason']
        return out

    field = ['--field', '0', '0.002', '0.001']
    plain = run('braided_chapter5.yaml', *field, '--dof', '3')
    interacting = run('braided_chapter5.yaml', *field, '--dof', '3', '--dipoles')
    assert interacting['dipoles']
    assert 1e-4 < np.linalg.norm(np.subtract(interacting['tip'], plain['tip'])) < 2e-3
    # The small-angle model within its range (this field turns the tip 0.16 rad; the one
    # above, 0.66 rad, is outside it: test_user_files.py).
    small = ['--field', '0', '0.0005', '0.00025']
    linear = run('braided_chapter5.yaml', *small, '--dof', '3', '--linear')
    plain = run('braided_chapter5.yaml', *small, '--dof', '3')
    assert linear['linear'] and linear['iterations'] == 1
    assert 1e-5 < np.linalg.norm(np.subtract(linear['tip'], plain['tip'])) < 1e-3
    # The chapter 6 strip with its backbone 20 mm out: the first 20 mm barely bend.
    strip = run('vsr_chapter6.yaml', '--field', '0', '0.01', '0', '--backbone', '0.02')
    free = run('vsr_chapter6.yaml', '--field', '0', '0.01', '0')
    assert strip['backbone_m'] == 0.02

    def deflection_of_first_20_mm(out):
        points = np.array(out['points'])
        along = np.cumsum(np.r_[0, np.linalg.norm(np.diff(points, axis=0), axis=1)])
        return np.max(np.abs(points[along <= 0.02 + 1e-9, 1]))

    assert deflection_of_first_20_mm(strip) < deflection_of_first_20_mm(free) / 50


def dipole_energy(m1, c1, m2, c2):
    """Textbook energy of two point dipoles, J."""
    r = c2 - c1
    d = np.linalg.norm(r)
    return 1e-7 / d ** 3 * (m1 @ m2 - 3 * (m1 @ r) * (m2 @ r) / d ** 2)


@pytest.mark.parametrize('dof', [1, 3])
def test_two_magnets_settle_where_a_brute_force_search_of_the_energy_does(dof):
    # Two 5 mm magnets end to end on a soft rod, both magnetised along it, bent by a field
    # across it: their attraction keeps them in line against the field. The reference
    # minimises the energy written out here from the textbook dipole formula with a
    # derivative-free search.
    from scipy.optimize import minimize
    from tentacle_model.tentacle_spec import parse_tentacle
    seg = {'length_m': 0.005, 'section': {'diameter_m': 0.001}, 'youngs_modulus_pa': 2e5,
           'density_kg_m3': 1400.0, 'magnetisation': {'remanence_t': 0.3,
                                                      'direction': [1, 0, 0]}}
    spec = parse_tentacle({'segments': [seg, seg]})
    chain = discretise(spec)
    b = np.array([0.0, 3e-3, 0.0])
    k = chain.stiffness_n_m[:, 0]
    h = chain.lengths_m
    m = chain.moments_a_m2[:, 0]

    def energy(theta):
        u = [np.array([np.cos(t), np.sin(t), 0.0]) for t in theta]
        moments = [mi * ui for mi, ui in zip(m, u)]
        c0, c1 = 0.5 * h[0] * u[0], h[0] * u[0] + 0.5 * h[1] * u[1]
        return (0.5 * k[0] * theta[0] ** 2 + 0.5 * k[1] * (theta[1] - theta[0]) ** 2
                - sum(mi @ b for mi in moments) + dipole_energy(moments[0], c0, moments[1], c1))

    # Folded back, the two point dipoles would meet: start the search in the unfolded basin.
    reference = minimize(energy, solve(chain, b).angles_rad, method='Nelder-Mead',
                         options={'xatol': 1e-10, 'fatol': 1e-16, 'maxiter': 20000}).x
    eq = solve(chain, b, dof=dof, dipoles=True, initial=None if dof == 1 else
               np.array([[0.0, 0, 0], [0.1, 0, 0]]))
    plain = solve(chain, b, dof=dof)
    assert eq.converged and eq.stability > 0
    angles = eq.angles_rad if dof == 1 else np.cumsum(eq.angles_rad[:, 0])
    np.testing.assert_allclose(angles, reference, atol=1e-6)
    assert np.linalg.norm(eq.tip_m - plain.tip_m) > 0.02 * spec.length_m  # it matters
    if dof == 3:
        assert np.max(np.abs(eq.angles_rad[:, 1:])) < 1e-9  # stays in the plane


@pytest.mark.parametrize('dof', [1, 3])
def test_magnets_that_fold_together_are_reported_not_collapsed(dof):
    # Strong magnets on a soft rod: point dipoles attract without bound as they meet, and
    # contact is not modelled, so the solve stops at contact and says which links touch.
    from tentacle_model.tentacle_spec import parse_tentacle
    seg = {'length_m': 0.005, 'section': {'diameter_m': 0.001}, 'youngs_modulus_pa': 2e5,
           'density_kg_m3': 1400.0, 'magnetisation': {'remanence_t': 0.5,
                                                      'direction': [1, 0, 0]}}
    chain = discretise(parse_tentacle({'segments': [seg, seg]}))
    eq = solve(chain, [0.0, 3e-3, 0.0], dof=dof, dipoles=True)
    assert not eq.converged and 'links 0 and 1 touch' in eq.reason
    assert np.all(np.isfinite(eq.points_m))
    gap = np.linalg.norm((eq.points_m[0] + eq.points_m[1]) / 2
                         - (eq.points_m[1] + eq.points_m[2]) / 2)
    assert gap >= 0.001 * (1 - 1e-9)  # stopped at the radii, never inside


@pytest.mark.parametrize('dof', [1, 3])
def test_the_compiled_newton_takes_the_generic_minimisers_steps(cantilever, braided, dof):
    # A chain without link loads is minimised compiled (spatial_newton, planar_newton): it
    # takes statics._minimise's steps (the generic loop the models with loads still run),
    # through indefinite Hessians, saddles and the step cap, to the same state and reason.
    from tentacle_model.statics import _minimise, _minimise_compiled, _Planar, _Spatial
    model, size = (_Spatial, 3) if dof == 3 else (_Planar, 1)
    rng = np.random.default_rng(5)
    reasons = set()
    # the straight rod antiparallel to a strong field: a saddle to leave (stiffer out of the
    # base plane: one escape direction, where a round rod's two are any pair of the plane)
    rod = discretise(cantilever[0], sublinks=8)
    rod = replace(rod, stiffness_n_m=rod.stiffness_n_m * [1.0, 1.5, 1.0])
    cases = [(rod, np.array([-5e-3, 0.0, 0.0]), np.zeros(3), np.zeros(8 * size), 200)]
    for trial in range(60):
        chain = discretise(braided, braided.length_m * rng.uniform(0.3, 1.0), 2)
        moments = chain.moments_a_m2 * rng.choice([-1.0, 1.0], size=(chain.size, 1))
        cases.append((replace(chain, moments_a_m2=moments), rng.uniform(-0.02, 0.02, 3),
                      np.array([0.0, -9.81, -9.81]), rng.normal(0.0, 0.4, size * chain.size),
                      int(rng.choice([3, 200]))))   # some run out of iterations
    for chain, field_t, gravity, start, iterations in cases:
        generic = _minimise(model(chain, field_t, gravity), start.copy(), 1e-9, iterations,
                            60.0, time.monotonic() + 60.0)
        compiled = _minimise_compiled(model(chain, field_t, gravity), start.copy(), 1e-9,
                                      iterations, 60.0, time.monotonic() + 60.0)
        assert compiled[1:3] == generic[1:3]
        assert compiled[0] == pytest.approx(generic[0], abs=1e-9)
        assert compiled[3] == pytest.approx(generic[3], rel=1e-6, abs=1e-12)
        if generic[4] is None:
            assert compiled[4] is None
        else:
            assert compiled[4] == pytest.approx(generic[4], rel=1e-9, abs=1e-15)
        reasons.add(generic[1].split(' in ')[0])
    assert reasons == {'converged', 'converged after leaving 1 saddle(s)', 'no convergence'}
