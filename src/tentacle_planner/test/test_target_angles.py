"""Joint angles along a target: forward kinematics lands on it, the twist is least strain."""

import math
import pathlib

import numpy as np
import pytest
from scipy.optimize import minimize
from tentacle_model import spatial
from tentacle_model.chain import discretise
from tentacle_model.tentacle_spec import load_tentacle, parse_tentacle
from tentacle_planner import target_angles
from tentacle_planner.errors import PlanInputError
from tentacle_planner.paths import Path, targets

ROOT = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope='module')
def braided():
    return load_tentacle(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml')


def rod(moduli, length_m=0.020, segments=1):
    """Return a spec of a 2 mm rod with these moduli (Pa: one, or bend_1, bend_2, twist)."""
    segment = {'length_m': length_m / segments, 'section': {'diameter_m': 0.002},
               'youngs_modulus_pa': moduli, 'density_kg_m3': 1000.0}
    return parse_tentacle({'segments': [segment] * segments})


def forward(chain, q):
    return spatial.evaluate(chain, q, np.zeros(3), hessian=False)


def energy(chain, q):
    return 0.5 * float(np.sum(chain.stiffness_n_m * q * q))


def arc(chain, radius_m, plane_normal_angle_deg=90.0):
    """Return the joints and tip of a chain laid on an arc bending towards u, chords = links."""
    tilt = math.radians(plane_normal_angle_deg)
    towards = np.array([0.0, math.cos(tilt), math.sin(tilt)])
    angles = np.concatenate([[0.0], np.cumsum(2 * np.arcsin(chain.lengths_m / (2 * radius_m)))])
    return (radius_m * np.sin(angles)[:, None] * [1.0, 0.0, 0.0]
            + radius_m * (1 - np.cos(angles))[:, None] * towards), angles


@pytest.mark.parametrize('inserted_m, sublinks', [(0.050, 1), (0.0333, 1), (0.041, 3)])
def test_joints_land_on_a_path_the_model_made(braided, inserted_m, sublinks):
    chain = discretise(braided, inserted_m, sublinks)
    made = np.random.default_rng(sublinks).uniform(-0.5, 0.5, (chain.size, 3))
    state = forward(chain, made)
    path = Path(state.points_m)
    np.testing.assert_allclose(targets(path, chain, inserted_m), state.points_m, rtol=0,
                               atol=1e-15)
    q = target_angles.target_joint_angles(path, chain, inserted_m)
    laid = forward(chain, q)
    np.testing.assert_allclose(laid.points_m, state.points_m, rtol=0, atol=1e-14)
    np.testing.assert_allclose(laid.rotations[:, :, 0], state.rotations[:, :, 0], atol=1e-12)
    assert energy(chain, q) < energy(chain, made)  # the same centreline, less twist


def brute_force(chain, directions):
    """Return the least energy over the twists, written out with rotation matrices."""
    def rz(a):
        return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0],
                         [0, 0, 1]])

    def ry(a):
        return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0],
                         [-math.sin(a), 0, math.cos(a)]])

    def rx(a):
        return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)],
                         [0, math.sin(a), math.cos(a)]])

    scale = chain.stiffness_n_m.max()

    def strain(twists):
        frame, total = chain.base_rotation, 0.0
        for i, d in enumerate(directions):
            u = frame.T @ d
            q = np.array([math.atan2(u[1], u[0]), -math.asin(u[2]), twists[i]])
            frame = frame @ rz(q[0]) @ ry(q[1]) @ rx(q[2])
            total += 0.5 * float(chain.stiffness_n_m[i] @ (q * q))
        return total / scale

    best = minimize(strain, np.zeros(len(directions)), method='BFGS',
                    options={'gtol': 1e-12, 'maxiter': 10_000})
    return best.fun * scale, best.x


@pytest.mark.parametrize('moduli', [1e5, {'bend_1': 5e5, 'bend_2': 5e5, 'twist': 1e7},
                                    {'bend_1': 1e5, 'bend_2': 3e5, 'twist': 2e5}])
def test_the_twist_is_that_of_least_strain_energy(moduli):
    chain = discretise(rod(moduli, 0.030, 6))
    rng = np.random.default_rng(11)
    state = forward(chain, rng.uniform(-0.6, 0.6, (chain.size, 3)))
    q = target_angles.angles_along(chain, state.rotations[:, :, 0])
    reference, twists = brute_force(chain, state.rotations[:, :, 0])
    assert energy(chain, q) <= reference * (1 + 1e-9)
    np.testing.assert_allclose(q[:, 2], twists, atol=1e-5)


def test_an_arc_out_of_the_base_plane_needs_no_twist():
    spec = rod(1e5)                               # isotropic: twist stiffness 2 EI / l
    chain = discretise(spec, sublinks=8)
    points, angles = arc(chain, 0.020)            # in the x-z plane, bending towards +z
    q = target_angles.target_joint_angles(Path(points), chain, spec.length_m)
    chord = np.diff(angles)                       # the turn of the chords, by hand
    expected = np.zeros((8, 3))
    expected[:, 1] = -np.concatenate([[chord[0] / 2], (chord[:-1] + chord[1:]) / 2])
    np.testing.assert_allclose(q, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(forward(chain, q).points_m, points, rtol=0, atol=1e-15)


@pytest.mark.parametrize('tilt_deg', [30, 45, 60])
def test_an_arc_in_a_tilted_plane_twists_hardly_at_all(braided, tilt_deg):
    for spec, sublinks in ((rod(1e5), 8), (braided, 2)):
        chain = discretise(spec, sublinks=sublinks)
        points, angles = arc(chain, 0.040, tilt_deg)
        q = target_angles.target_joint_angles(Path(points), chain, spec.length_m)
        np.testing.assert_allclose(forward(chain, q).points_m, points, rtol=0, atol=1e-15)
        bends = np.hypot(q[:, 0], q[:, 1])
        assert np.degrees(np.abs(q[:, 2])).max() < 0.01 * np.degrees(bends).max()


def test_a_flat_strip_rolls_into_its_soft_plane():
    # Stiff out of the base plane, soft in it and in twist: an arc out of the plane is
    # cheaper rolled at the clamp than bent the stiff way.
    spec = rod({'bend_1': 1e5, 'bend_2': 1e7, 'twist': 1e4})
    chain = discretise(spec, sublinks=8)
    points, _ = arc(chain, 0.020)
    q = target_angles.target_joint_angles(Path(points), chain, spec.length_m)
    np.testing.assert_allclose(forward(chain, q).points_m, points, rtol=0, atol=1e-15)
    untwisted = target_angles.angles_along(discretise(rod(1e5), sublinks=8),
                                           forward(chain, q).rotations[:, :, 0])
    assert energy(chain, q) < 0.2 * energy(chain, untwisted)
    assert 60 < abs(np.degrees(q[0, 2])) < 90
    assert np.all(np.abs(q[3:, 1]) < 0.01 * np.abs(q[3:, 0]))   # the rest bends the soft way


def test_a_bend_past_90_degrees_out_of_the_plane_is_a_plain_bend():
    spec = rod(1e5, 0.030, 3)
    chain = discretise(spec)
    up = math.radians(100)
    points = np.array([[0, 0, 0], [0.01, 0, 0], [0.01 + 0.01 * math.cos(up), 0,
                                                 0.01 * math.sin(up)]])
    points = np.vstack([points, points[-1] + [0, 0.01, 0]])
    q = target_angles.target_joint_angles(Path(points), chain, 0.030)
    np.testing.assert_allclose(np.degrees(q), [[0, 0, 0], [0, -100, 0], [90, 0, 0]],
                               atol=1e-9)
    np.testing.assert_allclose(forward(chain, q).points_m, points, rtol=0, atol=1e-15)


def test_links_on_a_curve_run_ahead_of_their_targets_by_the_chord_shortfall(braided):
    # A target chord on a curve is shorter than the link, which aims along it from where the
    # chain is: the chain runs ahead by the shortfalls so far, and hardly off the path.
    chain = discretise(braided)
    radius = 0.030
    s = np.linspace(0, 0.055, 1101)
    path = Path(np.column_stack([radius * np.sin(s / radius), 0.3 * s,
                                 radius * (1 - np.cos(s / radius))]))
    goal = targets(path, chain, 0.050)
    laid = forward(chain, target_angles.target_joint_angles(path, chain, 0.050)).points_m
    ahead = np.concatenate([[0.0], np.cumsum(chain.lengths_m
                                             - np.linalg.norm(np.diff(goal, axis=0), axis=1))])
    assert 0 < ahead[-1] < 0.005 * 0.050
    error = np.linalg.norm(laid - goal, axis=1)
    assert np.all((0.8 * ahead <= error) & (error <= ahead + 1e-15))
    dense = path.resample(1e-6)
    off_path = [np.linalg.norm(dense - p, axis=1).min() for p in laid]
    assert np.all(off_path <= 0.2 * ahead + 1e-6)


def test_a_fold_past_120_degrees_is_refused():
    chain = discretise(rod(1e5, 0.020, 2))
    back = math.radians(130)
    points = [[0, 0, 0], [0.01, 0, 0], [0.01 + 0.01 * math.cos(back), 0.01 * math.sin(back), 0]]
    with pytest.raises(PlanInputError, match='joint 1 would bend 130.0 degrees, more than '
                                             'the 120'):
        target_angles.angles_along(chain, np.diff(points, axis=0) / 0.01)
    # Along a path: named with the path and the step (the clamp joint, off the base direction).
    path = Path([[0, 0, 0], [-0.006, 0.008, 0], [-0.02, 0.008, 0]], 'duct.csv')
    with pytest.raises(PlanInputError, match='duct.csv: 20 mm inserted: joint 0 would bend '
                                             '126.9 degrees'):
        target_angles.target_joint_angles(path, chain, 0.020)
