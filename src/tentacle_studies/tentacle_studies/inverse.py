"""
Thesis chapter 2's learned inverse: desired deflections -> each magnet's magnetisation angle.

A grid study over the magnets' magnetisation angles with a point of interest per magnet
(config/studies/ch2_babble.yaml) is the thesis' "virtual motor babble". A deflection is a
point's displacement from the straight body along the base's normal (the thesis' x).
Turned past some angle a magnet deflects less again (thesis Fig. 2.5), so two angles give
one deflection and a network cannot learn the map: the thesis kept each magnet's angles
between those of its least and greatest deflection (redundancy_mask). A small network
(networks.py, Inverse) then maps the kept points' deflections to each
angle's cosine and sine, the thesis' six outputs. Its answers are checked in the forward
model (forward) and scored by the thesis' error (deflection_error). direct() finds the
angles by optimising in the forward model instead, as the planner does: slower, and
exact where the shape can be made.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from tentacle_studies import equilibria, networks

THESIS_LAYERS = (20,) * 6   # section 2.4.2: six hidden layers of 20
FULL_TURN_DEG = 360.0
FD_STEP_RAD = 1e-6           # direct(): forward differences of the deflections


class BabbleError(ValueError):
    """A study or table that is not a babble the inverse can learn from (says why)."""


@dataclass(frozen=True)
class Babble:
    """A magnetisation grid's deflections: grid[i, j, ...] is point (i, j, ...)."""

    names: tuple               # the varied names, magnetisation_deg.K, in the study's order
    angles_deg: tuple          # per name, its grid's angles (n_k,), deg
    deflections_m: np.ndarray  # (n_1, ..., n_k, k): name k's point of interest, m

    def points(self, mask):
        """Return (angles (N, k), rad, deflections (N, k), m) of the grid points in mask."""
        index = np.argwhere(mask)
        angles = np.column_stack([np.radians(a)[index[:, k]]
                                  for k, a in enumerate(self.angles_deg)])
        return angles, self.deflections_m[mask]

    def nearest(self, requested_m):
        """Return (N, k) angles, rad: for each requested shape (N, k), m, the grid's closest."""
        shapes = self.deflections_m.reshape(-1, self.deflections_m.shape[-1])
        index = [np.argmin(np.abs(shapes - want).sum(axis=1))
                 for want in np.atleast_2d(requested_m)]
        place = np.unravel_index(index, self.deflections_m.shape[:-1])
        return np.column_stack([np.radians(a)[i] for a, i in zip(self.angles_deg, place)])


def deflections(study, columns):
    """Return (N, k) each point of interest's deflection from a table's columns, m."""
    spec = study.tentacle
    direction, normal = spec.base_rotation[:, 0], spec.base_rotation[:, 1]
    return np.column_stack([
        (np.column_stack([columns[f'poi_{k}_{a}_m'] for a in 'xyz'])
         - spec.base_position_m - s * direction) @ normal
        for k, s in enumerate(study.points_of_interest_m)])


def babble(study, columns):
    """
    Return the Babble of a finished grid study's table ({column: (P,) values}).

    :raises BabbleError: not a grid of magnetisation angles only, each over a whole turn,
        with one point of interest per varied magnet, or the table not whole
    """
    names = tuple(study.names)
    if study.sample[0] != 'grid' or not all(n.startswith('magnetisation_deg.') for n in names):
        raise BabbleError(f'{study.name}: a babble is a grid over magnetisation_deg names '
                          f'only, not {study.sample[0]} over {", ".join(names)}')
    if len(study.points_of_interest_m) != len(names):
        raise BabbleError(f'{study.name}: {len(names)} magnets varied but '
                          f'{len(study.points_of_interest_m)} points_of_interest_m: one each')
    angles = tuple(v.grid() for v in study.varied)
    for name, a in zip(names, angles):
        step = np.diff(a)
        if len(a) < 3 or not np.allclose(step, FULL_TURN_DEG / len(a), atol=1e-9):
            raise BabbleError(f'{study.name}: {name} must step evenly through a whole turn '
                              f'(count values {FULL_TURN_DEG:g}/count apart), not {a}')
    rows = len(columns[names[0]]) if names[0] in columns else 0
    if rows != study.size:
        raise BabbleError(f'{study.name}: the table holds {rows} of {study.size} points: '
                          'finish it (tentacle-sweep --resume) first')
    shape = tuple(len(a) for a in angles)
    return Babble(names, angles, deflections(study, columns).reshape(shape + (len(names),)))


def redundancy_mask(grid):
    """
    Return (mask, arcs): the grid points kept, and per magnet the angle indices kept.

    A magnet's own deflection is its point's averaged over the other magnets' angles; its
    kept arc runs up (in angle, through 360 deg) from the angle of the least to that of the
    greatest, the half on which deflection rises with angle (thesis Fig. 2.5).
    """
    d = grid.deflections_m
    magnets = d.shape[-1]
    arcs = []
    for k in range(magnets):
        own = d[..., k].mean(axis=tuple(a for a in range(magnets) if a != k))
        low, high, n = int(np.argmin(own)), int(np.argmax(own)), len(own)
        arcs.append([(low + i) % n for i in range((high - low) % n + 1)])
    mask = np.zeros(d.shape[:-1], dtype=bool)
    mask[np.ix_(*arcs)] = True
    return mask, arcs


class Inverse:
    """Desired deflections (k,) -> magnetisation angles (k,): a fully connected network."""

    def __init__(self, layers=THESIS_LAYERS, activation='tanh', seed=0, max_iterations=5000):
        """
        Set up an untrained network.

        :param layers: hidden layer widths (the thesis': six of 20)
        :param activation: 'tanh' (the thesis' sigmoid, 'logistic', does not train through
            six layers by scikit-learn's solvers: it stays at the mean)
        :param seed: its initial weights
        :param max_iterations: L-BFGS iterations at most
        """
        self.network = networks.Network(layers, activation, seed, max_iterations)

    def fit(self, deflections_m, angles_rad):
        """Train on (N, k) deflections, m, and their (N, k) angles, rad; return self."""
        self.network.fit(deflections_m, np.hstack([np.cos(angles_rad), np.sin(angles_rad)]))
        return self

    def outputs(self, deflections_m):
        """Return (N, 2k) the network's cosines then sines of the angles."""
        return self.network(deflections_m)

    def angles_rad(self, deflections_m):
        """Return (N, k) the angles for (N, k) desired deflections, m, in (-pi, pi]."""
        out = self.outputs(deflections_m)
        k = out.shape[1] // 2
        return np.arctan2(out[:, k:], out[:, :k])


def forward(study, names, angles_rad):
    """
    Return (deflections (N, k), m, stable (N,)) of magnets named names at angles (N, k), rad.

    Each point is solved from the straight body (whatever the study's model.start), so an
    answer's deflection does not depend on the answers checked before it.
    """
    angles = np.atleast_2d(angles_rad)
    points = {name: np.degrees(angles[:, k]) for k, name in enumerate(names)}
    columns = equilibria.solve_at(study, points, warm=False)
    return deflections(study, columns), columns['stable']


def deflection_error(achieved_m, requested_m):
    """Return the thesis' error (section 2.7): sum |achieved - requested| / sum |requested|."""
    requested = np.asarray(requested_m, float)
    return float(np.abs(np.asarray(achieved_m) - requested).sum() / np.abs(requested).sum())


@dataclass(frozen=True)
class Direct:
    """direct()'s answer: the angles, rad, their deflections, m, and forward solves used."""

    angles_rad: np.ndarray
    deflections_m: np.ndarray
    stable: bool
    solves: int


def direct(study, names, requested_m, start_rad, max_evaluations=50):
    """
    Return the Direct of the angles whose deflections are nearest requested (k,), m.

    Least squares (scipy's trust region) in the forward model from start_rad (k,), the
    Jacobian by forward differences: each evaluation is one batch of k + 1 solves.
    """
    requested = np.asarray(requested_m, float)
    k = len(requested)
    solves = 0
    cache = {}

    def evaluate(x):
        nonlocal solves
        key = x.tobytes()
        if key not in cache:
            batch = np.vstack([x, x + FD_STEP_RAD * np.eye(k)])
            got, stable = forward(study, names, batch)
            solves += k + 1
            cache.clear()
            cache[key] = got, bool(stable[0])
        return cache[key]

    def residuals(x):
        return evaluate(x)[0][0] - requested

    def jacobian(x):
        got = evaluate(x)[0]
        return (got[1:] - got[0]).T / FD_STEP_RAD

    fit = least_squares(residuals, np.asarray(start_rad, float), jac=jacobian,
                        max_nfev=max_evaluations)
    got, stable = evaluate(fit.x)
    return Direct(fit.x, got[0], stable, solves)
