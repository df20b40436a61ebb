"""
A design study file (../shared/DESIGN.md, "Design studies"): what is fixed, what varies, where.

    name: ch2_babble
    compute: equilibrium              # or plan (then `scene:` instead of `tentacle:`)
    tentacle: ../tentacles/chapter2.yaml
    inserted_m: 0.042                 # optional: all
    field_t: [0.0, 0.005, 0.0]        # unless varied
    model: {dof: 1, sublinks: 8}      # also gravity_m_s2, start: previous or straight,
                                      # and twist_stability: true (dof 1)
    points_of_interest_m: [0.007, 0.021, 0.035]   # optional (beyond DESIGN.md): arc lengths
    vary:                             # a grid {from, to, count} or a list of values
      magnetisation_deg.0: {from: 0, to: 345, count: 24}
      field_t.y: [0.0, 0.005, 0.010]
    sample: grid                      # or {latin_hypercube: N, seed: S} or {random: N, seed: S}

Varied names: ``magnetisation_deg.K`` (segment K's magnetisation direction, at that angle in
its link x-y plane, deg, with the tentacle file's remanence) and ``field_t.x``, ``.y``,
``.z`` (tesla, world frame), or ``field_angle_deg`` with ``field_strength_t`` (the field in
the base's plane, at that angle from the base direction towards its normal, deg, and that
strong, T: both vary, or neither; a one-value list fixes one); and what makes the tentacle
itself (STRUCTURAL):
``youngs_modulus_pa.K`` (segment K's modulus, Pa, bending and twist alike),
``bend_modulus_pa.K`` and ``twist_modulus_pa.K`` (its bending moduli, or its twist one:
the pseudo-moduli of a reinforced segment), ``remanence_t.K`` (its remanence along its
file's direction, T), ``length_m.K`` (m), ``inserted_m`` and ``backbone_m`` (how far the
backbone reaches past the base, m; a tentacle with a backbone); ``fibre_angle_deg``,
``fibre_modulus_pa`` and ``fibre_diameter_m`` (a reinforced segment's fibres: to its axis,
deg, their Young's modulus, Pa, and diameter, m; ``.K`` segment K's, without it every
reinforced segment's: tentacle_model.reinforcement). A grid is every
combination, the last name varying fastest, so that neighbouring points are warm starts for
each other; a Latin hypercube or random sample draws N points: a range uniformly between
its ends (its count is the grid's only), a list one of its values. ``points_of_interest_m``
adds each such point's position along the body (arc length from the base) to the table:
columns ``poi_K_x_m``, ``_y_m``, ``_z_m`` after DESIGN.md's (the thesis' chapter 2 measured
its deflections at the magnets' centres).

A plan study (``compute: plan``, a ``scene:`` file in place of ``tentacle:``, its inserted
length, field and model the scene's) varies ``youngs_modulus_pa.K``, ``bend_modulus_pa.K``,
``twist_modulus_pa.K``, ``remanence_t.K`` and ``seed`` (a list of whole numbers): plans.py.

``model.start`` (beyond DESIGN.md): ``previous`` (default) solves each point from the one
before, as a rig sweeping its field goes; ``straight`` solves each from the straight body,
a tentacle of its own with its field switched on: where several equilibria are stable, the
one a point lands in then does not depend on its neighbours (a 3-DoF point takes more
Newton steps so). ``model.twist_stability: true`` (beyond DESIGN.md; dof 1) adds the column
``twist_stability``: the smallest eigenvalue of the 3-DoF stiffness at each planar
equilibrium, N m / rad^2; below zero the planar shape twists out of its plane (thesis
chapter 4's instability), nan where the point's magnets or field leave the plane.
"""

from dataclasses import dataclass
import hashlib
import math
import pathlib

import numpy as np
from scipy.stats import qmc
from tentacle_model.tentacle_spec import load_tentacle, SpecError
from tentacle_model.user_files import FieldReader, load_yaml, read_capped
import yaml

MAX_FILE_BYTES = 64 * 1024
SEGMENT_NAMES = ('magnetisation_deg', 'youngs_modulus_pa', 'bend_modulus_pa',
                 'twist_modulus_pa', 'remanence_t', 'length_m')
FIBRE_NAMES = ('fibre_angle_deg', 'fibre_modulus_pa', 'fibre_diameter_m')
"""A reinforced segment's fibres: .K segment K's, or without .K every reinforced one's."""
FIELD_POLAR = ('field_angle_deg', 'field_strength_t')
STRUCTURAL = ('youngs_modulus_pa', 'bend_modulus_pa', 'twist_modulus_pa', 'remanence_t',
              'length_m', 'inserted_m', 'backbone_m', *FIBRE_NAMES)
"""Name kinds that change the tentacle (its chain) from point to point."""
POSITIVE = ('youngs_modulus_pa', 'bend_modulus_pa', 'twist_modulus_pa', 'length_m',
            'fibre_modulus_pa', 'fibre_diameter_m')
MAX_POINTS = 10_000_000   # a study's points; each needs its row of every column in memory
AXES = {'x': 0, 'y': 1, 'z': 2}


class StudyError(ValueError):
    """A study file that cannot be run, naming the file and the key."""


@dataclass(frozen=True)
class Varied:
    """One varied name: a range (low, high; count for a grid) or a list of values."""

    name: str
    values: tuple = None
    low: float = None
    high: float = None
    count: int = None

    @property
    def length(self):
        """Return how many values the grid takes of this name (None: a range without count)."""
        return len(self.values) if self.values is not None else self.count

    @property
    def least(self):
        """Return the smallest value this name takes."""
        return min(self.values) if self.values is not None else min(self.low, self.high)

    @property
    def most(self):
        """Return the largest value this name takes."""
        return max(self.values) if self.values is not None else max(self.low, self.high)

    def grid(self):
        """Return the grid's values of this name (a range: count evenly spaced, ends in)."""
        if self.values is not None:
            return np.array(self.values, dtype=float)
        return np.linspace(self.low, self.high, self.count)

    def draw(self, u):
        """Return the values at uniform draws u in [0, 1): along a range, or from a list."""
        if self.values is not None:
            index = np.minimum((u * len(self.values)).astype(np.int64), len(self.values) - 1)
            return np.array(self.values, dtype=float)[index]
        return self.low + u * (self.high - self.low)


@dataclass(frozen=True)
class Study:
    """A validated study: the tentacle, what is fixed, what varies and how it is sampled."""

    name: str
    compute: str             # 'equilibrium'
    source: pathlib.Path     # the study file
    sha256: str              # of the study file's bytes: a resumed table must be its own
    tentacle: object         # a TentacleSpec
    inserted_m: float
    field_t: np.ndarray      # (3,) unless varied, T
    dof: int
    sublinks: int
    gravity_m_s2: np.ndarray
    varied: tuple            # of Varied, in the file's order
    sample: tuple            # ('grid', None, None) or (kind, count, seed)
    points_of_interest_m: tuple = ()   # arc lengths from the base, m
    warm: bool = True        # model.start: previous (True) or straight
    twist: bool = False      # model.twist_stability: the twist_stability column (dof 1)
    scene: object = None     # a plan study's Scene (tentacle_planner.scene)

    @property
    def names(self):
        """Return the varied names, in the file's order: the table's first columns."""
        return [v.name for v in self.varied]

    @property
    def size(self):
        """Return the number of points."""
        if self.sample[0] == 'grid':
            return math.prod(v.length for v in self.varied)
        return self.sample[1]

    def points(self, start=0, stop=None):
        """
        Return {name: (k,) values} of points start..stop (default all), in point order.

        A grid's point i is its row-major (C) index over the names; a sample's are drawn
        once from its seed, so any slice is the same whoever computes it.
        """
        stop = self.size if stop is None else min(stop, self.size)
        index = np.arange(start, stop)
        if self.sample[0] == 'grid':
            grids = [v.grid() for v in self.varied]
            place = np.unravel_index(index, [len(g) for g in grids])
            return {v.name: g[i] for v, g, i in zip(self.varied, grids, place)}
        u = self._draws()[start:stop]
        return {v.name: v.draw(u[:, k]) for k, v in enumerate(self.varied)}

    def _draws(self):
        kind, count, seed = self.sample
        if kind == 'latin_hypercube':
            return qmc.LatinHypercube(d=len(self.varied), seed=seed).random(count)
        return np.random.default_rng(seed).random((count, len(self.varied)))


def load_study(path):
    """
    Read and validate a study file (relative paths are from its folder).

    :raises StudyError: unreadable, not YAML, a key missing, unknown or invalid (named), its
        tentacle file refused, or more than MAX_POINTS points
    """
    path = pathlib.Path(path)
    data = read_capped(path, MAX_FILE_BYTES, StudyError, 'a study file')
    try:
        document = load_yaml(data.decode('utf-8'))
    except UnicodeDecodeError as exc:
        raise StudyError(f'{path}: not UTF-8 text ({exc.reason} at byte {exc.start})') \
            from None
    except yaml.YAMLError as exc:
        raise StudyError(f'{path}: not valid YAML: {exc}') from None
    reader = FieldReader(path, StudyError)
    doc = reader.mapping(document, 'study', ('name', 'compute', 'tentacle', 'scene',
                                             'inserted_m', 'field_t', 'model', 'vary',
                                             'sample', 'points_of_interest_m'),
                         ('name', 'vary'))
    compute = doc.get('compute', 'equilibrium')
    if compute == 'plan':
        return _plan_study(reader, doc, path, data)
    if compute != 'equilibrium':
        reader.fail('compute', f"{compute!r}: 'equilibrium' or 'plan'")
    if 'tentacle' not in doc or 'scene' in doc:
        reader.fail('tentacle', 'an equilibrium study names its tentacle file (and no scene)')
    try:
        tentacle = load_tentacle(path.parent / str(doc['tentacle']))
    except SpecError as exc:
        reader.fail('tentacle', str(exc))
    inserted = tentacle.length_m if doc.get('inserted_m') is None else reader.number(
        doc['inserted_m'], 'inserted_m')
    if inserted > tentacle.length_m * (1 + 1e-12):
        reader.fail('inserted_m', f'{inserted:g} m is more than the tentacle '
                                  f'({tentacle.length_m:g} m)')
    field = reader.vector(doc.get('field_t', [0.0, 0.0, 0.0]), 'field_t')
    model = reader.mapping(doc.get('model', {}), 'model',
                           ('dof', 'sublinks', 'gravity_m_s2', 'start', 'twist_stability'))
    dof = model.get('dof', 3)
    if dof not in (1, 3) or isinstance(dof, bool):
        reader.fail('model.dof', f'{dof!r} is not 1 or 3')
    sublinks = model.get('sublinks', 1)
    if isinstance(sublinks, bool) or not isinstance(sublinks, int) or not 1 <= sublinks <= 64:
        reader.fail('model.sublinks', f'{sublinks!r} is not a whole number from 1 to 64')
    gravity = reader.vector(model.get('gravity_m_s2', [0.0, 0.0, 0.0]), 'model.gravity_m_s2')
    start = model.get('start', 'previous')
    if start not in ('previous', 'straight'):
        reader.fail('model.start', f"{start!r} is not 'previous' or 'straight'")
    twist = reader.flag(model.get('twist_stability', False), 'model.twist_stability')
    if twist and dof != 1:
        reader.fail('model.twist_stability', "that of a planar equilibrium: give 'dof: 1'")
    varied = _varied(reader, doc['vary'], tentacle)
    if any(v.name == 'seed' for v in varied):
        reader.fail('vary.seed', 'only a plan study (compute: plan) has a seed: an equilibrium '
                                 'has none')
    shortest = tentacle.length_m - sum(
        tentacle.segments[int(v.name.split('.')[1])].length_m - v.least
        for v in varied if v.name.startswith('length_m.'))
    for v in varied:
        if v.name in ('inserted_m', 'backbone_m') and v.most > shortest * (1 + 1e-12):
            reader.fail(f'vary.{v.name}', f'{v.most:g} m is more than the tentacle '
                                          f'({shortest:g} m at its shortest)')
    sample = _sample(reader, doc.get('sample', 'grid'), varied)
    interest = doc.get('points_of_interest_m') or []
    if not isinstance(interest, list):
        reader.fail('points_of_interest_m', f'expected a list of arc lengths, got {interest!r}')
    interest = tuple(reader.number(v, f'points_of_interest_m[{i}]', allow_zero=True)
                     for i, v in enumerate(interest))
    least_inserted = min([inserted] + [v.least for v in varied if v.name == 'inserted_m'])
    for i, s in enumerate(interest):
        if s > least_inserted * (1 + 1e-12):
            reader.fail(f'points_of_interest_m[{i}]', f'{s:g} m is past the inserted '
                                                      f'{least_inserted:g} m')
    study = Study(str(doc['name']), compute, path, hashlib.sha256(data).hexdigest(), tentacle,
                  inserted, field, dof, sublinks, gravity, varied, sample, interest,
                  start == 'previous', twist)
    if study.size > MAX_POINTS:
        reader.fail('vary', f'{study.size} points: at most {MAX_POINTS}')
    return study


PLAN_NAMES = ('youngs_modulus_pa', 'bend_modulus_pa', 'twist_modulus_pa', 'remanence_t',
              *FIBRE_NAMES, 'seed')


def _plan_study(reader, doc, path, data):
    """Return the Study of a plan study: its scene, what varies of its tentacle, seeds."""
    from tentacle_planner.errors import PlanInputError   # plan studies only
    from tentacle_planner.scene import load_scene
    if 'scene' not in doc or 'tentacle' in doc:
        reader.fail('scene', 'a plan study names its scene file (and no tentacle)')
    for key in ('inserted_m', 'field_t', 'model', 'points_of_interest_m'):
        if key in doc:
            reader.fail(key, 'a plan study takes it from its scene: leave it out')
    try:
        scene = load_scene(path.parent / str(doc['scene']))
    except PlanInputError as exc:
        reader.fail('scene', str(exc))
    vary = doc['vary']
    for name in (vary if isinstance(vary, dict) else {}):
        if str(name).partition('.')[0] not in PLAN_NAMES:
            reader.fail(f'vary.{name}', 'a plan study varies youngs_modulus_pa.K, '
                                        'bend_modulus_pa.K, twist_modulus_pa.K, '
                                        'remanence_t.K (segment K), fibre_angle_deg, '
                                        'fibre_modulus_pa, fibre_diameter_m or seed')
    varied = _varied(reader, vary, scene.tentacle)
    sample = _sample(reader, doc.get('sample', 'grid'), varied)
    settings = scene.model
    study = Study(str(doc['name']), 'plan', path, hashlib.sha256(data).hexdigest(),
                  scene.tentacle, scene.tentacle.length_m, np.zeros(3), settings.dof,
                  settings.sublinks, np.asarray(settings.gravity_m_s2, float), varied, sample,
                  scene=scene)
    if study.size > MAX_POINTS:
        reader.fail('vary', f'{study.size} points: at most {MAX_POINTS}')
    return study


def _varied(reader, vary, tentacle):
    """Return the Varied of a vary block, each name checked against the tentacle."""
    if not isinstance(vary, dict) or not vary:
        reader.fail('vary', 'expected a mapping of at least one name')
    out = []
    for name, spec in vary.items():
        where = f'vary.{name}'
        kind, _, which = str(name).partition('.')
        if kind in SEGMENT_NAMES:
            _check_segment(reader, where, tentacle, which)
            if kind in ('magnetisation_deg', 'remanence_t') and not np.any(
                    tentacle.segments[int(which)].magnetisation_a_per_m):
                reader.fail(where, f'segment {which} is not magnetised: it has no direction')
        elif kind == 'seed' and not which:
            pass
        elif kind in FIBRE_NAMES:
            _check_reinforced(reader, where, tentacle, which)
        elif kind in FIELD_POLAR and not which:
            pass
        elif kind == 'backbone_m' and tentacle.backbone is None:
            reader.fail(where, 'the tentacle has no backbone (its file has no backbone: block)')
        elif not (kind == 'field_t' and which in AXES) and not (
                kind in ('inserted_m', 'backbone_m') and not which):
            reader.fail(where, 'unknown name: magnetisation_deg.K, youngs_modulus_pa.K, '
                               'bend_modulus_pa.K, twist_modulus_pa.K, remanence_t.K, '
                               'length_m.K (segment K), fibre_angle_deg, fibre_modulus_pa, '
                               'fibre_diameter_m (.K or every reinforced segment), field_t.x, '
                               '.y, .z, field_angle_deg with field_strength_t, inserted_m or '
                               'backbone_m')
        if isinstance(spec, list):
            if not spec:
                reader.fail(where, 'an empty list')
            out.append(_checked(reader, where, kind, Varied(
                str(name), tuple(reader.number(v, f'{where}[{i}]', positive=False)
                                 for i, v in enumerate(spec)))))
            continue
        spec = reader.mapping(spec, where, ('from', 'to', 'count'), ('from', 'to'))
        count = spec.get('count')
        if count is not None and (isinstance(count, bool) or not isinstance(count, int)
                                  or count < 1):
            reader.fail(f'{where}.count', f'{count!r} is not a whole number of at least 1')
        out.append(_checked(reader, where, kind, Varied(
            str(name), None, reader.number(spec['from'], f'{where}.from', False),
            reader.number(spec['to'], f'{where}.to', False), count)))
    kinds = {v.name.partition('.')[0] for v in out}
    if len(kinds & set(FIELD_POLAR)) == 1 or (kinds & set(FIELD_POLAR) and 'field_t' in kinds):
        reader.fail('vary', 'field_angle_deg and field_strength_t vary together (a one-value '
                            'list fixes one), and without field_t.x, .y, .z')
    for v in out:
        if v.name.startswith('fibre_diameter_m'):
            for k in _reinforced(tentacle, v.name.partition('.')[2]):
                segment = tentacle.segments[k]
                if segment.reinforcement.radius_m + v.most / 2 > segment.radius_m:
                    reader.fail(f'vary.{v.name}', f"{v.most:g} m: segment {k}'s fibres on "
                                                  f'{segment.reinforcement.radius_m:g} m '
                                                  'would stand outside its section')
    return tuple(out)


def _reinforced(tentacle, which):
    """Return the segments a fibre name with suffix which ('K' or '') changes."""
    if which:
        return [int(which)]
    return [k for k, s in enumerate(tentacle.segments) if s.reinforcement is not None]


def _check_segment(reader, where, tentacle, which):
    """Refuse a name's segment number which (its '.K') that the tentacle does not have."""
    if not which.isdigit() or int(which) >= len(tentacle.segments):
        reader.fail(where, f'segment {which!r}: the tentacle has segments 0 to '
                           f'{len(tentacle.segments) - 1}')


def _check_reinforced(reader, where, tentacle, which):
    """Refuse a fibre name whose segment (or, without .K, the tentacle) has no fibres."""
    if which:
        _check_segment(reader, where, tentacle, which)
    if which and tentacle.segments[int(which)].reinforcement is None:
        reader.fail(where, f'segment {which} has no reinforcement (a reinforcement: block in '
                           'its tentacle file)')
    if not _reinforced(tentacle, which):
        reader.fail(where, 'the tentacle has no reinforced segment (a reinforcement: block '
                           'in a segment of its file)')


def _checked(reader, where, kind, varied):
    """Return varied, its values in the name's range (a modulus or length above zero...)."""
    if kind in POSITIVE and varied.least <= 0:
        reader.fail(where, f'{varied.least:g}: a {kind} must be above zero')
    if kind in ('remanence_t', 'inserted_m', 'backbone_m', 'field_strength_t') \
            and varied.least < 0:
        reader.fail(where, f'{varied.least:g}: a {kind} cannot be negative')
    if kind == 'fibre_angle_deg' and not 0 <= varied.least <= varied.most <= 90:
        reader.fail(where, f'{varied.least:g} to {varied.most:g}: a fibre angle to the axis is '
                           'from 0 to 90 deg')
    if kind == 'seed' and (varied.values is None or varied.least < 0 or any(
            v != int(v) for v in varied.values)):
        reader.fail(where, 'seeds are a list of whole numbers from 0')
    return varied


def _sample(reader, sample, varied):
    """Return ('grid', None, None) or (kind, count, seed) of a sample entry."""
    if sample == 'grid':
        for v in varied:
            if v.values is None and v.count is None:
                reader.fail(f'vary.{v.name}', 'a grid needs a count for a range')
        return 'grid', None, None
    kinds = [k for k in sample if k in ('latin_hypercube', 'random')] \
        if isinstance(sample, dict) else []
    if len(kinds) != 1:
        reader.fail('sample', f'{sample!r}: grid, {{latin_hypercube: N, seed: S}} or '
                              '{random: N, seed: S}')
    reader.mapping(sample, 'sample', (kinds[0], 'seed'))
    count, seed = sample[kinds[0]], sample.get('seed', 0)
    for key, value, least in ((kinds[0], count, 1), ('seed', seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            reader.fail(f'sample.{key}', f'{value!r} is not a whole number of at least {least}')
    if count > MAX_POINTS:
        reader.fail(f'sample.{kinds[0]}', f'{count} points: at most {MAX_POINTS}')
    return kinds[0], count, seed
