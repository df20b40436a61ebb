"""
Scene files (DESIGN.md, "Scenes and schedules"): what a plan is made for, validated.

::

    name: pancreatic_duct                       # optional: the file's stem
    tentacle: ../tentacles/braided_chapter5.yaml  # relative to this file
    path: {points_m: [[0, 0, 0], ...]}          # or {file: duct.mrk.json}; frame: rig | image
    insertion_steps_m: [0.010, 0.020, 0.030]    # increasing, in (0, tentacle length]
    playback_step_m: 0.001                      # optional
    coil: {max_field_t: 0.020, max_total_field_t: 0.030, max_field_change_t: 0.015}
    obstacles: [{centre_m: [x, y, z], radius_m: r}]   # or {walls: [{points_m: [...]}]}
    clearance_margin_m: 0.0002                  # optional: plans keep the body this far off
    model: {dof: 3, sublinks: 1, gravity_m_s2: [0, 0, 0], dipoles: false}
    magnetisation: {planar: false, max_neighbour_angle_deg: 60, distal_axial: false,
                    given: false}           # given: the tentacle file's directions, fields only
    mismatch: {stiffness_factor: 0.9, remanence_factor: 1.05, insertion_offset_m: [0, 3e-4, 0],
               insertion_angle_deg: 1.5, actuation_matrix_factor: [1.03, 0.97, 1.0]}
                                            # the simulated rig only (mismatch.py): the plan
                                            # is made for the tentacle file as it is

A backbone schedule (thesis chapter 6; beyond DESIGN.md's keys, which it keeps) replaces the
path with a coiling target and moves the backbone instead of the body::

    coiling: {radius_m: 0.0075, side: 1}    # straight to the backbone's end, then this arc,
                                            # towards the base normal (side -1: away)
    insertion_steps_m: [0.08]               # one for every step, or one each
    backbone_steps_m: [0.0775, 0.075, ...]  # its reach past the base at each key step

Required: tentacle, insertion_steps_m, and path or coiling (coiling with backbone_steps_m).
Steps: at most MAX_KEY_STEPS; each, the advance between two and playback_step_m at least
MIN_STEP_M; at most MAX_PLAYBACK_STEPS dense steps.
Every other key is optional, and so is each key of coil, model and magnetisation: an omitted
limit is no limit, an omitted switch is off, and the model defaults to 3-DoF joints, one link
per segment, no gravity, no magnet-to-magnet interaction. coil limits: max_field_t each
axis, max_total_field_t the magnitude |B|, max_field_change_t each axis between consecutive
steps (all T). Obstacles and walls are in the rig frame; plans keep the body (its radius
included) clearance_margin_m off them (default CLEARANCE_MARGIN_M; 0: the body may graze
them). Unknown keys, missing required ones, wrong types and values out of range are refused
naming the file and the key.

The path is placed at the tentacle's base pose (paths.py) and must then be at least as long
as the deepest insertion step, turn no more than the model's links can follow, from the clamp
on (paths.check_followable with the longest link of the chain at the deepest step), lie in
the base plane for a planar model (within paths.START_TOLERANCE_M) and keep out of every
spherical obstacle. The model's size is checked as the solver would (statics.check_size).
"""

import dataclasses
from dataclasses import dataclass, field
import hashlib
import pathlib

import numpy as np
from tentacle_model import statics
from tentacle_model.chain import discretise
from tentacle_model.model import TentacleModel
from tentacle_model.tentacle_spec import load_tentacle, SpecError, TentacleSpec
from tentacle_model.user_files import FieldReader, load_yaml, read_capped
from tentacle_planner import paths
from tentacle_planner.errors import PlanInputError
from tentacle_planner.mismatch import Mismatch, read_mismatch
from tentacle_planner.schedule_file import ModelSettings, read_model_settings
import yaml

MAX_FILE_BYTES = 64 * 1024  # as a tentacle file: PyYAML takes up to a second on this much
TOP_KEYS = ('name', 'tentacle', 'path', 'insertion_steps_m', 'playback_step_m', 'coil',
            'obstacles', 'model', 'magnetisation', 'backbone_steps_m', 'coiling', 'mismatch',
            'clearance_margin_m')
REQUIRED_KEYS = ('tentacle', 'insertion_steps_m')
CLEARANCE_MARGIN_M = 2e-4  # how far plans keep the body off obstacles and walls by default
MAX_CLEARANCE_MARGIN_M = 0.01
COIL_PATH_STEP_M = 0.25e-3  # the points of a coiling target, this far apart
COIL_KEYS = ('max_field_t', 'max_total_field_t', 'max_field_change_t')
MAGNETISATION_KEYS = ('planar', 'max_neighbour_angle_deg', 'distal_axial', 'given')
MIN_STEP_M = 1e-5
"""
The smallest insertion step, m: a key step's inserted length, the advance between two key
steps and playback_step_m are at least this (10 um; the rig's stages step 0.1 mm and more).
"""
MAX_KEY_STEPS = 200  # key steps (or backbone positions): every evaluation solves each one
MAX_PLAYBACK_STEPS = 2000  # dense steps (deepest key step / playback_step_m): a fit each


@dataclass(frozen=True)
class CoilLimits:
    """Field limits, T; None: no such limit."""

    max_field_t: float | None = None         # each axis, every step
    max_total_field_t: float | None = None   # |B|, every step
    max_field_change_t: float | None = None  # each axis, between consecutive steps


@dataclass(frozen=True, eq=False)
class Sphere:
    """A spherical obstacle, rig frame."""

    centre_m: np.ndarray   # (3,)
    radius_m: float


@dataclass(frozen=True, eq=False)
class Wall:
    """Points on a wall the body keeps off, rig frame."""

    points_m: np.ndarray   # (k, 3)


@dataclass(frozen=True)
class MagnetisationLimits:
    """Constraints on the planned magnetisation; None or False: none."""

    planar: bool = False                          # directions in the link's x-y plane
    max_neighbour_angle_deg: float | None = None  # between neighbouring segments
    distal_axial: bool = False                    # the tip segment magnetised along its axis
    given: bool = False                           # the tentacle file's directions: fields only


@dataclass(frozen=True, eq=False)
class Scene:
    """A validated scene: the tentacle, the rig-frame path and the limits of a plan."""

    name: str
    source: pathlib.Path          # the scene file
    sha256: str                   # of the scene file's bytes, hex
    tentacle_file: pathlib.Path
    tentacle: TentacleSpec
    path: paths.Path              # rig frame, from the insertion point
    insertion_steps_m: tuple      # increasing
    playback_step_m: float | None
    coil: CoilLimits
    obstacles: tuple              # Sphere
    walls: tuple                  # Wall
    model: ModelSettings
    magnetisation: MagnetisationLimits
    backbone_steps_m: tuple | None = None   # the backbone's reach past the base per key step
    coiling_radius_m: float | None = None   # the target coils at this radius past the backbone
    coiling_side: int = 1                   # +1: towards the base normal (link y), -1: away
    mismatch: Mismatch = Mismatch()         # how the simulated rig differs from the model
    clearance_margin_m: float = CLEARANCE_MARGIN_M  # plans keep the body this far off, m
    _coil_paths: dict = field(default_factory=dict, repr=False)  # backbone m -> Path, built once

    def target_path(self, inserted_m, backbone_m=0.0):
        """
        Return the Path a step's body is to lie along (rig frame).

        The scene's path; for a coiling scene, the body straight along the insertion
        direction as far as the backbone reaches, then an arc of coiling_radius_m.
        """
        if self.coiling_radius_m is None:
            return self.path
        key = round(float(backbone_m), 12)
        if key not in self._coil_paths:
            self._coil_paths[key] = coiling_path(self.tentacle, backbone_m,
                                                 self.coiling_radius_m, self.coiling_side,
                                                 f'{self.source}: coiling')
        return self._coil_paths[key]

    def shape_error(self, step):
        """Return (shape RMS, tip error), m, of a Step (paths.shape_error, DESIGN.md)."""
        return paths.shape_error(step.points_m, self.target_path(step.inserted_m,
                                                                 step.backbone_m),
                                 step.inserted_m)

    def own_directions(self):
        """Return the tentacle file's magnetisation directions (segments, 3); 0: passive."""
        m = np.array([seg.magnetisation_a_per_m for seg in self.tentacle.segments])
        norms = np.linalg.norm(m, axis=1)
        return np.divide(m, norms[:, None], out=np.zeros_like(m), where=norms[:, None] > 0)

    def tentacle_model(self, **options):
        """Return a TentacleModel of the scene's tentacle and model settings (options override)."""
        return TentacleModel(self.tentacle, **{**self.model.as_options(), **options})


def coiling_path(spec, straight_m, radius_m, side, source):
    """
    Return a Path from the base: straight_m along the insertion direction, then an arc.

    :param radius_m: the arc's radius, m; it turns towards the base normal for side +1
    """
    origin, rotation = spec.base_position_m, spec.base_rotation
    s = np.arange(0.0, spec.length_m + 2 * COIL_PATH_STEP_M, COIL_PATH_STEP_M)
    turned = np.maximum(s - straight_m, 0.0) / radius_m      # rad, past the backbone's end
    along = np.minimum(s, straight_m) + radius_m * np.sin(turned)
    across = side * radius_m * (1 - np.cos(turned))
    points = origin + along[:, None] * rotation[:, 0] + across[:, None] * rotation[:, 1]
    return paths.Path(points, source)


def load_scene(path):
    """
    Read and validate a scene file.

    :param path: the scene YAML file
    :return: a Scene
    :raises PlanInputError: an unreadable, oversized, empty or malformed file (a key given
        twice is malformed), a key unknown, missing, of the wrong type or out of range, or
        a tentacle or path file that is; the message names the file and the key (and the
        point of a path)
    """
    source = pathlib.Path(path)
    data = read_capped(source, MAX_FILE_BYTES, PlanInputError,
                       'a scene file (put a long path in a file of its own)')
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise PlanInputError(f'{source}: not UTF-8 text ({exc.reason} at byte {exc.start})') \
            from None
    try:
        document = load_yaml(text)
    except yaml.YAMLError as exc:  # a repeated key too
        raise PlanInputError(f'{source}: not valid YAML: {exc}') from None
    except RecursionError:
        raise PlanInputError(f'{source}: not valid YAML: nested too deeply') from None
    if document is None:
        raise PlanInputError(f'{source}: empty file')
    return parse_scene(document, source, hashlib.sha256(data).hexdigest())


def scene_of(tentacle, path, insertion_steps_m=None, *, frame=None, **keys):
    """
    Return a Scene from a tentacle file and a path file, without a scene file.

    The Python API behind ``tentacle-plan --tentacle FILE --path FILE``: every other scene
    key (coil, model, magnetisation, obstacles, playback_step_m, name) is a keyword with the
    scene file's meaning and the same checks.

    :param tentacle: the tentacle file
    :param path: the path file (.csv, .npy, .mrk.json, .fcsv)
    :param insertion_steps_m: the key steps; default: the end of every segment the path
        is long enough for
    :param frame: the path's frame, 'rig' or 'image' (default: the file's own)
    :raises PlanInputError: as load_scene, naming the file or the key
    """
    tentacle, path = pathlib.Path(tentacle).resolve(), pathlib.Path(path).resolve()
    source = pathlib.Path.cwd() / '(command line)'
    block = {'file': str(path)} if frame is None else {'file': str(path), 'frame': frame}
    if insertion_steps_m is None:
        try:
            spec = load_tentacle(tentacle)
        except SpecError as exc:
            raise PlanInputError(str(exc)) from None
        placed = paths.load_path(block, spec.base_position_m, spec.base_rotation,
                                 source.parent, source)
        ends = np.cumsum([segment.length_m for segment in spec.segments])
        insertion_steps_m = [float(e) for e in ends if e <= placed.length_m * (1 + 1e-9)]
        if not insertion_steps_m:
            raise PlanInputError(f'{path}: the path, {placed.length_m * 1e3:.4g} mm, is '
                                 f'shorter than the first segment, {ends[0] * 1e3:.4g} mm')
    document = {'name': keys.pop('name', path.name.split('.')[0]), 'tentacle': str(tentacle),
                'path': block, 'insertion_steps_m': list(insertion_steps_m),
                **{k: v for k, v in keys.items() if v is not None}}
    scene = parse_scene(document, source)
    # What a scene file's digest is: of everything the plan is made from.
    digest = hashlib.sha256(tentacle.read_bytes() + path.read_bytes()
                            + repr(sorted(document.items(), key=str)).encode()).hexdigest()
    return dataclasses.replace(scene, sha256=digest)


def parse_scene(document, source, sha256=''):
    """
    Return a Scene from a parsed scene document.

    :param document: the parsed YAML
    :param source: the scene file: messages name it, relative files are relative to it
    :param sha256: of the scene file's bytes
    :raises PlanInputError: as load_scene
    """
    source = pathlib.Path(source)
    read = FieldReader(source, PlanInputError)
    doc = read.mapping(document, 'top level', TOP_KEYS, REQUIRED_KEYS)
    name = doc.get('name', source.stem)
    if not isinstance(name, str) or not name.strip():
        read.fail('name', f'expected a non-empty string, got {name!r}')
    tentacle_file, spec = _tentacle(read, doc['tentacle'], source)
    model = read_model_settings(read, doc.get('model', {}))
    if ('path' in doc) == ('coiling' in doc):
        read.fail('top level', 'give either path (a centreline to follow) or coiling (coil '
                  'past the backbone, with backbone_steps_m)')
    backbones = None
    if 'backbone_steps_m' in doc:
        steps, backbones = _backbone_steps(read, doc, spec)
    else:
        steps = _steps(read, doc['insertion_steps_m'], spec)
    playback = doc.get('playback_step_m')
    if playback is not None and backbones is not None:
        read.fail('playback_step_m', 'dense playback of a backbone schedule is not supported: '
                  'give every backbone position as a key step')
    if playback is not None:
        playback = read.number(playback, 'playback_step_m')
        if playback > steps[-1]:
            read.fail('playback_step_m', f'{playback:g} m is more than the deepest insertion '
                      f'step, {steps[-1]:g} m')
        if playback < MIN_STEP_M:
            read.fail('playback_step_m', f'{playback:g} m is less than the smallest step, '
                      f'{MIN_STEP_M:g} m')
        if steps[-1] / playback > MAX_PLAYBACK_STEPS:
            read.fail('playback_step_m', f'{playback:g} m makes {steps[-1] / playback:.0f} '
                      f'dense steps to {steps[-1]:g} m, more than the {MAX_PLAYBACK_STEPS} '
                      f'planned at most: take at least {steps[-1] / MAX_PLAYBACK_STEPS:.3g} m')
    try:
        chain = discretise(spec, steps[-1], model.sublinks)
        statics.check_size(chain.size, model.dof,
                           chain.interacting_pair_count() if model.dipoles else 0)
    except ValueError as exc:  # ProblemTooLarge is one
        read.fail('model.sublinks', str(exc))
    coiling = (None, 1) if 'coiling' not in doc else _coiling(read, doc, backbones)
    if coiling[0] is None:
        path = paths.load_path(doc['path'], spec.base_position_m, spec.base_rotation,
                               source.parent, source)
    else:  # the deepest step's target stands for the path (the picture, the schedule)
        path = coiling_path(spec, backbones[-1], *coiling, f'{source}: coiling')
    deepest = len(steps) - 1
    if path.length_m < steps[-1] * (1 - 1e-9):
        read.fail(f'insertion_steps_m[{deepest}]',
                  f'{steps[-1] * 1e3:.4g} mm is more than the length of the path, '
                  f'{path.length_m * 1e3:.4g} mm ({path.source})')
    paths.check_followable(path, float(np.max(chain.lengths_m)), spec.base_rotation[:, 0])
    if model.dof == 1:
        _check_in_base_plane(path, spec)
    coil = read.mapping(doc.get('coil', {}), 'coil', COIL_KEYS)
    coil = CoilLimits(*(read.optional_number(coil, k, 'coil') for k in COIL_KEYS))
    spheres, walls = _obstacles(read, doc.get('obstacles', []))
    for index, sphere in enumerate(spheres):
        _check_clear(read, path, sphere, index)
    magnetisation = _magnetisation(read, doc.get('magnetisation', {}))
    mismatch = read_mismatch(read, doc.get('mismatch', {}))
    margin = read.number(doc.get('clearance_margin_m', CLEARANCE_MARGIN_M),
                         'clearance_margin_m', allow_zero=True)
    if margin > MAX_CLEARANCE_MARGIN_M:
        read.fail('clearance_margin_m', f'{margin:g} m is more than {MAX_CLEARANCE_MARGIN_M:g}'
                  ' m: a margin, not a channel width')
    return Scene(name, source, sha256, tentacle_file, spec, path, steps, playback, coil,
                 spheres, walls, model, magnetisation, backbones, *coiling, mismatch=mismatch,
                 clearance_margin_m=margin)


def _tentacle(read, value, source):
    if not isinstance(value, str) or not value.strip():
        read.fail('tentacle', f'expected a tentacle file name, got {value!r}')
    file = source.parent / value
    try:
        return file, load_tentacle(file)
    except SpecError as exc:
        read.fail('tentacle', str(exc))


def _backbone_steps(read, doc, spec):
    """Return (insertion steps, backbone steps): one insertion for all, or one per step."""
    raw = doc['backbone_steps_m']
    if spec.backbone is None:
        read.fail('backbone_steps_m', f'the tentacle {spec.name!r} has no backbone (its file '
                  'has no backbone: block)')
    if not isinstance(raw, list) or not raw:
        read.fail('backbone_steps_m', f'expected a non-empty list of backbone reaches past '
                  f'the base (m), got {raw!r}')
    if len(raw) > MAX_KEY_STEPS:
        read.fail('backbone_steps_m', f'{len(raw)} steps, more than the {MAX_KEY_STEPS} a '
                  'scene may have')
    backbones = [read.number(v, f'backbone_steps_m[{i}]', allow_zero=True)
                 for i, v in enumerate(raw)]
    inserted = _steps(read, doc['insertion_steps_m'], spec, increasing=False)
    if len(inserted) == 1:
        inserted = inserted * len(backbones)
    if len(inserted) != len(backbones):
        read.fail('backbone_steps_m', f'{len(backbones)} backbone steps for '
                  f'{len(inserted)} insertion steps: give one insertion for all, or one each')
    for i, (a, b) in enumerate(zip(inserted, backbones)):
        if b > a * (1 + 1e-12):
            read.fail(f'backbone_steps_m[{i}]', f'{b:g} m reaches past the inserted length, '
                      f'{a:g} m')
    return tuple(inserted), tuple(backbones)


def _coiling(read, doc, backbones):
    """Return (radius m, side) of a coiling block."""
    raw = read.mapping(doc['coiling'], 'coiling', ('radius_m', 'side'), ('radius_m',))
    if backbones is None:
        read.fail('coiling', 'a coiling target needs backbone_steps_m: the body coils past '
                  'the backbone')
    side = raw.get('side', 1)
    if side not in (1, -1) or isinstance(side, bool):
        read.fail('coiling.side', f'expected 1 (towards the base normal) or -1, got {side!r}')
    return read.number(raw['radius_m'], 'coiling.radius_m'), int(side)


def _steps(read, raw, spec, increasing=True):
    if not isinstance(raw, list) or not raw:
        read.fail('insertion_steps_m', f'expected a non-empty list of inserted lengths (m), '
                  f'got {raw!r}')
    if len(raw) > MAX_KEY_STEPS:
        read.fail('insertion_steps_m', f'{len(raw)} steps, more than the {MAX_KEY_STEPS} a '
                  'scene may have')
    steps = []
    for i, value in enumerate(raw):
        where = f'insertion_steps_m[{i}]'
        step = read.number(value, where)
        if step > spec.length_m * (1 + 1e-12):
            read.fail(where, f'{step:g} m is more than the length of the tentacle, '
                      f'{spec.length_m:g} m')
        if step < MIN_STEP_M:
            read.fail(where, f'{step:g} m is less than the smallest step, {MIN_STEP_M:g} m')
        if steps and (step <= steps[-1] if increasing else step < steps[-1]):
            read.fail(where, f'{step:g} m does not increase on insertion_steps_m[{i - 1}] '
                      f'({steps[-1]:g} m): steps are in insertion order')
        if steps and step != steps[-1] and step - steps[-1] < MIN_STEP_M:
            read.fail(where, f'{step:g} m is {step - steps[-1]:.3g} m past '
                      f'insertion_steps_m[{i - 1}] ({steps[-1]:g} m): steps are at least '
                      f'{MIN_STEP_M:g} m apart')
        steps.append(min(step, spec.length_m))
    return tuple(steps)


def _obstacles(read, raw):
    """Return (spheres, walls): a list of spheres, or {walls: [{points_m: [...]}, ...]}."""
    if isinstance(raw, dict):
        raw = read.mapping(raw, 'obstacles', ('walls',), ('walls',))
        if not isinstance(raw['walls'], list):
            read.fail('obstacles.walls', f'expected a list of {{points_m: [...]}}, got '
                      f'{raw["walls"]!r}')
        walls = []
        for i, wall in enumerate(raw['walls']):
            where = f'obstacles.walls[{i}]'
            wall = read.mapping(wall, where, ('points_m',), ('points_m',))
            walls.append(Wall(read.points(wall['points_m'], f'{where}.points_m')))
        return (), tuple(walls)
    if not isinstance(raw, list):
        read.fail('obstacles', 'expected a list of {centre_m, radius_m} or {walls: [...]}, '
                  f'got {type(raw).__name__}')
    spheres = []
    for i, sphere in enumerate(raw):
        where = f'obstacles[{i}]'
        sphere = read.mapping(sphere, where, ('centre_m', 'radius_m'), ('centre_m', 'radius_m'))
        spheres.append(Sphere(read.vector(sphere['centre_m'], f'{where}.centre_m'),
                              read.number(sphere['radius_m'], f'{where}.radius_m')))
    return tuple(spheres), ()


def _magnetisation(read, raw):
    raw = read.mapping(raw, 'magnetisation', MAGNETISATION_KEYS)
    angle = read.optional_number(raw, 'max_neighbour_angle_deg', 'magnetisation')
    if angle is not None and angle > 180:
        read.fail('magnetisation.max_neighbour_angle_deg', f'{angle:g} degrees is more than '
                  '180 (no limit: leave the key out)')
    return MagnetisationLimits(read.flag(raw.get('planar', False), 'magnetisation.planar'),
                               angle,
                               read.flag(raw.get('distal_axial', False),
                                         'magnetisation.distal_axial'),
                               read.flag(raw.get('given', False), 'magnetisation.given'))


def _check_in_base_plane(path, spec):
    """Refuse a path out of the base plane for a planar model."""
    normal = spec.base_rotation[:, 2]
    off = np.abs((path.points_m - spec.base_position_m) @ normal)
    worst = int(np.argmax(off))
    if off[worst] > paths.START_TOLERANCE_M:
        raise PlanInputError(
            f'{path.source}: point {worst} is {off[worst] * 1e3:.3g} mm out of the base plane: '
            'a planar model (model.dof 1) bends in it only (within '
            f'{paths.START_TOLERANCE_M * 1e3:g} mm); use model.dof 3')


def _check_clear(read, path, sphere, index):
    """Refuse a path that runs through a spherical obstacle."""
    a, b = path.points_m[:-1], path.points_m[1:]
    ab = b - a
    t = np.clip(np.sum((sphere.centre_m - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0, 1)
    gap = np.linalg.norm(a + t[:, None] * ab - sphere.centre_m, axis=1)
    inside = np.flatnonzero(gap < sphere.radius_m)
    if len(inside):
        i = int(inside[0])
        read.fail(f'obstacles[{index}]', f'the path runs through it between points {i} and '
                  f'{i + 1} ({path.source}), {gap[i] * 1e3:.3g} mm from its centre, radius '
                  f'{sphere.radius_m * 1e3:.3g} mm')
