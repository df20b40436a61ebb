"""
Schedule files (DESIGN.md "Scenes and schedules"): the format, and reading one back typed.

``read_schedule(path)`` returns a ``Schedule``: the planned tentacle (a tentacle-file
document), the planning model's settings, the path and every step, checked as strictly as a
scene (the message names the file and the key). This module imports neither matplotlib nor
scipy nor the model's solvers, so a node loads a schedule in milliseconds; the writer is
schedule_writer.py, the picture plan_plot.py.
"""

from dataclasses import dataclass
import math
import pathlib

import numpy as np
from tentacle_model.user_files import FieldReader, load_yaml, read_capped
from tentacle_planner.errors import PlanInputError

FORMAT = 'tentacle-schedule/1'
MAX_SCHEDULE_BYTES = 16 << 20  # a 50-step playback with a 2000-point path is under 1 MiB
MODEL_KEYS = ('dof', 'sublinks', 'gravity_m_s2', 'dipoles')
TOP_KEYS = ('format', 'scene', 'tentacle', 'model', 'magnetisation_deg', 'path_m',
            'path_thinned', 'steps', 'robustness', 'verification', 'flags', 'interrupted')
STEP_KEYS = ('insertion_m', 'key', 'field_t', 'predicted_centreline_m', 'shape_rms_m',
             'tip_error_m', 'stability', 'backbone_m', 'clearance_m')


@dataclass(frozen=True)
class ModelSettings:
    """What a forward model includes (tentacle_model.model.TentacleModel's options)."""

    dof: int = 3
    sublinks: int = 1
    gravity_m_s2: tuple = (0.0, 0.0, 0.0)
    dipoles: bool = False

    def as_options(self):
        """Return the TentacleModel keyword arguments."""
        return {'dof': self.dof, 'sublinks': self.sublinks,
                'gravity_m_s2': self.gravity_m_s2, 'dipoles': self.dipoles}


def read_model_settings(read, raw, where='model'):
    """Return the ModelSettings of a scene's or schedule's model block (omitted keys: off)."""
    raw = read.mapping(raw, where, MODEL_KEYS)
    dof = raw.get('dof', 3)
    if isinstance(dof, bool) or dof not in (1, 3):
        read.fail(f'{where}.dof', f'expected 1 (planar joints) or 3 (bend, bend, twist), got '
                  f'{dof!r}')
    sublinks = raw.get('sublinks', 1)
    if isinstance(sublinks, bool) or not isinstance(sublinks, int) or sublinks < 1:
        read.fail(f'{where}.sublinks', f'expected a whole number >= 1, got {sublinks!r}')
    gravity = tuple(float(g) for g in read.vector(raw.get('gravity_m_s2', [0.0, 0.0, 0.0]),
                                                  f'{where}.gravity_m_s2'))
    dipoles = read.flag(raw.get('dipoles', False), f'{where}.dipoles')
    return ModelSettings(int(dof), sublinks, gravity, dipoles)


@dataclass(frozen=True)
class ScheduleStep:
    """One step to play: where the body should be and the field that puts it there."""

    insertion_m: float                 # inserted length, m
    field_t: np.ndarray                # (3,) tesla, frame coils
    predicted_centreline_m: np.ndarray  # (k, 3) m, frame coils, base to tip
    shape_rms_m: float                 # planned shape error against the path, m
    tip_error_m: float                 # m
    stability: float                   # smallest Hessian eigenvalue, N m/rad^2; > 0 stable
    key: bool = True                   # a key step (False: a dense playback step)
    backbone_m: float | None = None    # the backbone's reach past the base, m
    clearance_m: float | None = None   # least distance to the phantom, m (negative: inside)


@dataclass(frozen=True, eq=False)
class Schedule:
    """A schedule file, read."""

    source: pathlib.Path
    scene_name: str
    scene_sha256: str
    tentacle: dict            # the planned tentacle, in the tentacle-file schema
    model: ModelSettings      # the planning model
    path_m: np.ndarray        # (N, 3) m, frame coils (thinned when path_thinned says so)
    steps: tuple              # ScheduleStep, in insertion order
    flags: tuple              # str
    interrupted: bool         # Ctrl-C: the best plan found so far

    @property
    def key_steps(self):
        """Return the key steps only."""
        return tuple(s for s in self.steps if s.key)

    def tentacle_spec(self):
        """Return the planned tentacle as a TentacleSpec (tentacle_model.tentacle_spec)."""
        from tentacle_model.tentacle_spec import parse_tentacle, SpecError
        try:
            return parse_tentacle(self.tentacle, f'{self.source}: tentacle')
        except SpecError as exc:
            raise PlanInputError(str(exc)) from None


def _real(read, value, where):
    """Return a float that may be infinite (a stability with nothing inserted), not NaN."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
        read.fail(where, f'expected a number, got {value!r}')
    return float(value)


def _step(read, raw, where):
    raw = read.mapping(raw, where, STEP_KEYS, required=(
        'insertion_m', 'field_t', 'predicted_centreline_m', 'shape_rms_m', 'tip_error_m',
        'stability'))

    def optional(key, positive):
        value = raw.get(key)
        return None if value is None else read.number(value, f'{where}.{key}', positive,
                                                      allow_zero=True)
    return ScheduleStep(
        insertion_m=read.number(raw['insertion_m'], f'{where}.insertion_m', allow_zero=True),
        field_t=read.vector(raw['field_t'], f'{where}.field_t'),
        predicted_centreline_m=read.points(raw['predicted_centreline_m'],
                                           f'{where}.predicted_centreline_m'),
        shape_rms_m=read.number(raw['shape_rms_m'], f'{where}.shape_rms_m', allow_zero=True),
        tip_error_m=read.number(raw['tip_error_m'], f'{where}.tip_error_m', allow_zero=True),
        stability=_real(read, raw['stability'], f'{where}.stability'),
        key=read.flag(raw.get('key', True), f'{where}.key'),
        backbone_m=optional('backbone_m', True), clearance_m=optional('clearance_m', False))


def read_schedule(path):
    """
    Return the Schedule in a schedule file.

    :raises PlanInputError: the file is missing, not a regular file, over MAX_SCHEDULE_BYTES,
        not UTF-8 or YAML, of another format, or a key is missing, unknown or malformed (the
        message names the file and the key); a schedule written before schedules recorded
        their planning model is refused with the advice to plan again
    """
    path = pathlib.Path(path)
    data = read_capped(path, MAX_SCHEDULE_BYTES, PlanInputError, 'a schedule file')
    read = FieldReader(str(path), PlanInputError)
    try:
        document = load_yaml(data.decode('utf-8'))
    except UnicodeDecodeError as exc:
        read.fail('file', f'not UTF-8 text ({exc.reason} at byte {exc.start})')
    except Exception as exc:  # yaml.YAMLError and the duplicate-key refusal
        read.fail('file', f'not YAML: {exc}')
    document = read.mapping(document, 'schedule', TOP_KEYS,
                            required=('format', 'scene', 'tentacle', 'path_m', 'steps'))
    if document['format'] != FORMAT:
        read.fail('format', f'{document["format"]!r} is not a format this reader knows '
                  f'({FORMAT})')
    if 'model' not in document:
        read.fail('model', 'missing: this schedule predates recorded planning models; plan '
                  'it again (tentacle-plan) to play it')
    scene = read.mapping(document['scene'], 'scene', ('name', 'sha256'), ('name', 'sha256'))
    if not isinstance(document['tentacle'], dict):
        read.fail('tentacle', 'expected the tentacle-file mapping')
    steps = document['steps']
    if not isinstance(steps, list) or not steps:
        read.fail('steps', f'expected a non-empty list of steps, got {steps!r}')
    parsed = tuple(_step(read, raw, f'steps[{i}]') for i, raw in enumerate(steps))
    for i in range(1, len(parsed)):
        if parsed[i].insertion_m < parsed[i - 1].insertion_m:
            read.fail(f'steps[{i}].insertion_m', f'{parsed[i].insertion_m:g} m after '
                      f'{parsed[i - 1].insertion_m:g} m: steps go in insertion order')
    flags = document.get('flags', [])
    if not isinstance(flags, list) or not all(isinstance(f, str) for f in flags):
        read.fail('flags', f'expected a list of text, got {flags!r}')
    return Schedule(
        source=path, scene_name=str(scene['name']), scene_sha256=str(scene['sha256']),
        tentacle=document['tentacle'], model=read_model_settings(read, document['model']),
        path_m=read.points(document['path_m'], 'path_m'), steps=parsed, flags=tuple(flags),
        interrupted=read.flag(document.get('interrupted', False), 'interrupted'))
