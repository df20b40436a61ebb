"""Forward statics against closed forms and an independent boundary-value solution."""

import json
import pathlib
import time

import numpy as np
import pytest
from scipy.integrate import solve_bvp
from tentacle_planner import planar
from tentacle_planner.chain import discretise
from tentacle_planner.statics import solve_planar


def field(magnitude_t, degrees):
    phi = np.radians(degrees)
    return magnitude_t * np.array([np.cos(phi), np.sin(phi), 0.0])


def elastica_tip(length, ei, ma, b_t, degrees):
    """Tip (x, y) of E I theta'' + M A B sin(phi - theta) = 0, theta(0) = 0, theta'(L) = 0."""
    phi, c = np.radians(degrees), ma * b_t / ei

    def rhs(s, y):
        return np.vstack([y[1], -c * np.sin(phi - y[0]), np.cos(y[0]), np.sin(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    s = np.linspace(0, length, 400)
    bend = 1.5 * np.sin(np.pi * s / (2 * length))  # a buckled guess, bending towards +y
    guess = np.vstack([bend, np.gradient(bend, s), s, np.zeros_like(s)])
    sol = solve_bvp(rhs, bc, s, guess, tol=1e-8, max_nodes=200000)
    assert sol.status == 0, sol.message
    return sol.y[2:, -1]


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
    from tentacle_planner.statics_cli import main
    path = pathlib.Path(__file__).resolve().parents[3] / 'config/tentacles/cantilever.yaml'
    code = main(['--tentacle', str(path), '--field', '0', '0.005',
                 '0', '--sublinks', '64', '--json'])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out['converged'] is True and out['stability'] > 0
    np.testing.assert_allclose(out['tip'], [0.010675, 0.015271, 0.0], atol=3e-6)  # NOTES.md
    assert main(['--tentacle', 'nope.yaml', '--field', '0', '0', '0']) == 2
    assert 'nope.yaml' in capsys.readouterr().err


def test_command_line_three_dof_out_of_plane(capsys):
    from tentacle_planner.statics_cli import main
    path = pathlib.Path(__file__).resolve().parents[3] / 'config/tentacles/cantilever.yaml'
    assert main(['--tentacle', str(path), '--field', '0', '0', '0.005', '--dof', '3',
                 '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['converged'] and out['tip'][2] > 0.01 and abs(out['tip'][1]) < 1e-12
