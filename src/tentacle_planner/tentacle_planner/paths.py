"""
Desired paths: read, placed at the insertion pose, sampled by arc length, followed by the leader.

A path is the centreline the tentacle should follow, from the insertion point (the tentacle's
base position) on. Where it comes from:

- ``points_m`` in a scene: ``[[x, y, z], ...]``, metres;
- CSV: ``#`` lines are comments; a header row names the columns ``x_<unit>``, ``y_<unit>``,
  ``z_<unit>`` (unit ``m``, ``mm`` or ``um``; other columns are ignored), one point a row;
- ``.npy``: a (k, 3) array of numbers, metres (its header is checked before it is loaded);
- 3D Slicer ``.mrk.json``: the first markup only (as Slicer loads it), a Curve or a point list
  (``Fiducial``); ``coordinateSystem`` LPS (the default) or RAS, ``coordinateUnits`` mm (the
  default), um or m, also as a UCUM coded entry; a point whose position is undefined (or only
  a preview) is refused;
- legacy Slicer ``.fcsv``: millimetres; ``# CoordinateSystem = LPS`` or ``RAS`` (older files
  0 = RAS, 1 = LPS; without the line LPS, as Slicer reads it); columns id,x,y,z,... at fixed
  places as Slicer reads them (a ``# columns`` line that says otherwise is refused).

A path file has at most MAX_PATH_POINTS points (checked before they are parsed). Slicer
coordinates are taken as RAS, the frame Slicer shows (LPS to RAS negates x and y). Point
numbers in messages count from 0, in the order of the file.

Frames: ``rig`` (the default for inline points, CSV and npy): the points are rig coordinates
and the first is the insertion point, within START_TOLERANCE_M of the tentacle's base position.
``image`` (the default for Slicer files): the path is moved rigidly so that its first point is
at the base position, its initial direction (the chord over its first INITIAL_DIRECTION_M) is
the base insertion direction and its first bend (the first point past that chord more than
BEND_ANGLE_DEG off it, seen from the start) lies towards the base normal, in the base plane.

Between its points a path is linear in arc length: exact for a polyline. (Slicer draws a Curve
as a spline through its control points; between sparse control points the two differ, so
resample such a curve densely in Slicer, or give it the Linear curve type.)

Turns. Two consecutive segments may turn by at most MAX_TURN_DEG. A chain of rigid links lies
along a path with its joints on it only if the path turns by at most that much between any two
consecutive chords one link long, nor leaves the insertion point more than that off the
insertion direction (check_followable): past 120 degrees the neighbouring links
fold onto each other (their centres come within half their straight distance, where
tentacle_model.chain.contact_distances puts contact). On a circular arc of radius R and links
of length h the chords turn by h / R: the radius of curvature must be at least
3 h / (2 pi), about 0.48 h.
"""

import csv
import io
import json
import math
import pathlib
import re

import numpy as np
from tentacle_model.user_files import read_capped
from tentacle_planner.errors import PlanInputError

START_TOLERANCE_M = 0.5e-3   # a rig-frame path's first point from the base position, at most
INITIAL_DIRECTION_M = 2e-3   # arc length over which an image path's initial direction is taken
BEND_ANGLE_DEG = 1.0         # seen from the start, how far off the initial chord a bend begins
MAX_TURN_DEG = 120.0         # between consecutive segments, and consecutive link-long chords
SHAPE_SAMPLES = 15  # the fewest points along the body a shape error is taken at (DESIGN.md)
MIN_SEGMENT_M = 1e-9         # consecutive points closer than this are one point repeated
MAX_FILE_BYTES = 32 * 2 ** 20
"""
The largest path file read, bytes (it reads at most one byte more).

Slicer writes about 0.85 kB of JSON a control point: 32 MiB is some 38,000 points, read and
checked in half a second here (a centreline has a few points a millimetre).
"""
MAX_PATH_POINTS = 1_000_000
"""
The most points a path file may hold; more are refused before they are parsed.

A .npy's header is read first and its shape checked against this (a 176-byte file may claim
10^12 points: loading it would allocate them). Checking and planning along a million
points takes about 2 s here; the schedule carries a long path thinned (schedule_writer.py).
"""
UNITS_M = {'m': 1.0, 'mm': 1e-3, 'um': 1e-6}
SLICER_TYPES = ('Curve', 'Fiducial')  # Fiducial: Slicer's name for a point list
SLICER_SYSTEMS = {'LPS': 'LPS', 'RAS': 'RAS', '0': 'RAS', '1': 'LPS'}  # digits: older .fcsv
FCSV_POSITION_STATUS = 14  # column of positionStatus in .fcsv (0 undefined, 1 preview, 2 defined)
FRAMES = ('rig', 'image')
_AXIS_COLUMN = re.compile(r'^\s*([xyz])(?:_(.*?))?\s*$', re.IGNORECASE)


class Path:
    """A centreline: points (k, 3) in m and linear interpolation in arc length between them."""

    def __init__(self, points_m, source='<path>'):
        """
        Validate the points of a path.

        :param points_m: (k, 3) m, k >= 2, in order from the insertion point
        :param source: what messages name (a file, a scene key)
        :raises PlanInputError: fewer than two points, not (k, 3) numbers, a point not finite,
            a point repeated, a turn of more than MAX_TURN_DEG between consecutive segments
        """
        self.source = str(source)
        try:
            points = np.array(points_m, dtype=float)
        except (TypeError, ValueError):
            raise PlanInputError(f'{self.source}: expected a list of [x, y, z] points') from None
        if points.ndim != 2 or points.shape[1] != 3:
            raise PlanInputError(f'{self.source}: expected points of three coordinates, got an '
                                 f'array of shape {points.shape}')
        if len(points) < 2:
            raise PlanInputError(f'{self.source}: a path needs at least two points, got '
                                 f'{len(points)}')
        bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
        if len(bad):
            raise PlanInputError(f'{self.source}: point {bad[0]}: {points[bad[0]].tolist()} is '
                                 'not finite')
        steps = np.diff(points, axis=0)
        lengths = np.linalg.norm(steps, axis=1)
        short = np.flatnonzero(lengths <= MIN_SEGMENT_M)
        if len(short):
            i = short[0]
            raise PlanInputError(f'{self.source}: point {i + 1} repeats point {i} '
                                 f'({points[i].tolist()}): remove one of them')
        turns = _angles_deg(steps[:-1], steps[1:])
        sharp = np.flatnonzero(turns > MAX_TURN_DEG)
        if len(sharp):
            i = sharp[0] + 1
            raise PlanInputError(f'{self.source}: point {i}: the path turns {turns[i - 1]:.1f} '
                                 f'degrees there, more than the {MAX_TURN_DEG:g} a tentacle '
                                 'can take (points out of order?)')
        arcs = np.concatenate([[0.0], np.cumsum(lengths)])
        points.setflags(write=False)
        arcs.setflags(write=False)
        self._points, self._arcs = points, arcs

    @property
    def points_m(self):
        """Return the points (k, 3), m (read-only)."""
        return self._points

    @property
    def arc_lengths_m(self):
        """Return each point's arc length from the first (k,), m (read-only)."""
        return self._arcs

    @property
    def length_m(self):
        """Return the arc length from the first point to the last, m."""
        return float(self._arcs[-1])

    def at(self, arc_lengths_m):
        """
        Return the points at arc lengths from the first point: (k, 3) m, or (3,) for a scalar.

        Linear between the path's points; a path point is returned exactly at its own arc
        length.

        :param arc_lengths_m: (k,) or scalar, m, in [0, length_m]
        :raises PlanInputError: an arc length outside the path (beyond a rounding margin)
        """
        s = np.asarray(arc_lengths_m, dtype=float)
        scalar = s.ndim == 0
        s = np.atleast_1d(s)
        margin = 1e-9 * self.length_m
        outside = ~((s >= -margin) & (s <= self.length_m + margin))  # NaN is outside too
        if np.any(outside):
            bad = s[outside][0]
            raise PlanInputError(f'{self.source}: arc length {bad:g} m is outside the path '
                                 f'(0 to {self.length_m:g} m)')
        s = np.clip(s, 0.0, self.length_m)
        arcs = self._arcs
        index = np.clip(np.searchsorted(arcs, s, side='right') - 1, 0, len(arcs) - 2)
        t = ((s - arcs[index]) / (arcs[index + 1] - arcs[index]))[:, None]
        out = (1.0 - t) * self._points[index] + t * self._points[index + 1]
        return out[0] if scalar else out

    def resample(self, step_m):
        """Return points (m + 1, 3) evenly spaced in arc length, at most step_m apart."""
        if not step_m > 0:
            raise ValueError(f'step {step_m} m must be positive')
        count = max(1, math.ceil(self.length_m / step_m - 1e-9))
        return self.at(np.linspace(0.0, self.length_m, count + 1))

    def moved(self, rotation, translation_m):
        """Return this path moved rigidly: x -> rotation x + translation_m."""
        return Path(self._points @ np.asarray(rotation, dtype=float).T
                    + np.asarray(translation_m, dtype=float), self.source)


def _angles_deg(a, b):
    """Return the angles between the rows of (k, 3) arrays a and b, degrees."""
    na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    with np.errstate(invalid='ignore', divide='ignore'):
        cos = np.sum(a * b, axis=1) / (na * nb)
    cos = np.where(np.isfinite(cos), cos, -1.0)  # a zero-length chord: as good as a reversal
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _unit(vector):
    return vector / np.linalg.norm(vector)


def rotation_between(a, b):
    """Return the smallest rotation (3, 3) that turns direction a onto direction b."""
    a, b = _unit(np.asarray(a, dtype=float)), _unit(np.asarray(b, dtype=float))
    axis = np.cross(a, b)
    sin, cos = np.linalg.norm(axis), float(a @ b)
    if sin < 1e-12:
        if cos > 0:
            return np.eye(3)
        # Opposite: a half turn about any axis perpendicular to a.
        other = np.eye(3)[np.argmin(np.abs(a))]
        axis = _unit(np.cross(a, other))
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    return np.eye(3) + k + k @ k * ((1.0 - cos) / sin ** 2)


def image_to_rig(path, base_position_m, base_rotation):
    """
    Return a path in image coordinates moved rigidly onto the insertion pose.

    Its first point goes to the base position, its initial direction (the chord over the first
    INITIAL_DIRECTION_M of arc) to the base insertion direction, and its first bend towards the
    base normal (base_rotation's second column): the first point past that chord seen more
    than BEND_ANGLE_DEG off it from the start. A path with no such point is turned by the
    smallest rotation that aligns the directions.

    :param path: a Path
    :param base_position_m: (3,) m
    :param base_rotation: (3, 3) columns: insertion direction, base normal, their cross product
    """
    base_rotation = np.asarray(base_rotation, dtype=float)
    points, arcs = path.points_m, path.arc_lengths_m
    start = points[0]
    direction = _unit(path.at(min(INITIAL_DIRECTION_M, path.length_m)) - start)
    later = points[arcs > INITIAL_DIRECTION_M] - start
    along = later @ direction
    across = later - along[:, None] * direction
    off = np.linalg.norm(across, axis=1) > math.sin(math.radians(BEND_ANGLE_DEG)) \
        * np.linalg.norm(later, axis=1)
    if np.any(off):
        bend = _unit(across[np.argmax(off)])
        frame = np.column_stack([direction, bend, np.cross(direction, bend)])
        rotation = base_rotation @ frame.T
    else:
        rotation = rotation_between(direction, base_rotation[:, 0])
    return path.moved(rotation, np.asarray(base_position_m, dtype=float) - rotation @ start)


def place(path, frame, base_position_m, base_rotation):
    """
    Return a path in the rig frame, from rig or image coordinates (module docstring).

    :param frame: 'rig' (checked to start at the base position) or 'image' (moved there)
    :raises PlanInputError: a rig-frame path that does not start at the base position
    """
    if frame == 'image':
        return image_to_rig(path, base_position_m, base_rotation)
    if frame != 'rig':
        raise ValueError(f'frame {frame!r} is not one of {FRAMES}')
    base = np.asarray(base_position_m, dtype=float)
    gap = float(np.linalg.norm(path.points_m[0] - base))
    if gap > START_TOLERANCE_M:
        raise PlanInputError(
            f'{path.source}: point 0 {path.points_m[0].tolist()} m is {gap * 1e3:.3g} mm from '
            f'the tentacle base position {base.tolist()} m: a path in the rig frame starts '
            f'at the insertion point (within {START_TOLERANCE_M * 1e3:g} mm); give frame: '
            'image to have it moved there')
    return path


def load_path(block, base_position_m, base_rotation, directory='.', source='<scene>'):
    """
    Return the rig-frame Path of a scene's ``path`` block.

    :param block: ``{points_m: [[x, y, z], ...]}`` or ``{file: NAME}``, and optionally
        ``frame: rig | image``
    :param base_position_m: (3,) the tentacle's base position, m
    :param base_rotation: (3, 3) its base rotation (tentacle_spec.TentacleSpec)
    :param directory: what a relative file name is relative to (the scene file's folder)
    :param source: the scene file, for messages
    :raises PlanInputError: naming the scene, the key and, for a file, the file and the point
    """
    where = f'{source}: path'
    if not isinstance(block, dict):
        raise PlanInputError(f'{where}: expected a mapping with points_m or file, got '
                             f'{type(block).__name__}')
    unknown = sorted(set(block) - {'points_m', 'file', 'frame'}, key=repr)
    if unknown:
        raise PlanInputError(f'{where}: unknown key(s) {unknown}; allowed: '
                             "['file', 'frame', 'points_m']")
    if ('points_m' in block) == ('file' in block):
        raise PlanInputError(f'{where}: give either points_m or file')
    frame = block.get('frame')
    if frame is not None and frame not in FRAMES:
        raise PlanInputError(f'{where}.frame: {frame!r} is not one of {list(FRAMES)}')
    if 'points_m' in block:
        path = Path(_inline_points(block['points_m'], f'{where}.points_m'),
                    f'{where}.points_m')
        return place(path, frame or 'rig', base_position_m, base_rotation)
    name = block['file']
    if not isinstance(name, str) or not name.strip():
        raise PlanInputError(f'{where}.file: expected a file name, got {name!r}')
    file = pathlib.Path(directory) / name
    try:
        points, default_frame = read_path_file(file)
    except PlanInputError as exc:
        raise PlanInputError(f'{where}.file: {exc}') from None
    return place(Path(points, f'{where}.file: {file}'), frame or default_frame,
                 base_position_m, base_rotation)


def _inline_points(raw, where):
    """Return a scene's inline points as floats, naming the point of a malformed one."""
    if not isinstance(raw, list):
        raise PlanInputError(f'{where}: expected a list of [x, y, z] points, got '
                             f'{type(raw).__name__}')
    points = []
    for i, point in enumerate(raw):
        if not isinstance(point, list) or len(point) != 3:
            raise PlanInputError(f'{where}[{i}]: expected [x, y, z], got {point!r}')
        row = []
        for value in point:
            if isinstance(value, str):  # YAML 1.1 reads 1e-3 (no dot) as a string
                try:
                    value = float(value)
                except ValueError:
                    pass
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise PlanInputError(f'{where}[{i}]: expected three numbers, got {point!r}')
            row.append(float(value))
        points.append(row)
    return points


def read_path_file(file):
    """
    Return the points of a path file, m, and the frame they are in by default.

    :param file: a .csv, .npy, .mrk.json (or .json) or .fcsv file (module docstring)
    :return: (points (k, 3) m, 'rig' or 'image'); Slicer files' points are RAS
    :raises PlanInputError: a missing, unreadable, empty, oversized or malformed file, an
        unknown unit or coordinate system, an undefined point; naming the file and the line,
        key or point
    """
    file = pathlib.Path(file)
    name = file.name.lower()
    kinds = (('.mrk.json', _read_markups), ('.json', _read_markups), ('.fcsv', _read_fcsv),
             ('.csv', _read_csv), ('.npy', _read_npy))
    reader = next((read for suffix, read in kinds if name.endswith(suffix)), None)
    if reader is None:
        raise PlanInputError(f'{file}: unknown kind of path file: give a .mrk.json, .fcsv, '
                             '.csv or .npy file')
    data = read_capped(file, MAX_FILE_BYTES, PlanInputError, 'a path file')
    if not data.strip():
        raise PlanInputError(f'{file}: empty file')
    if reader is _read_npy:
        return _read_npy(data, file), 'rig'
    try:
        text = data.decode('utf-8-sig')
    except UnicodeDecodeError as exc:
        raise PlanInputError(f'{file}: not UTF-8 text ({exc.reason} at byte {exc.start})') \
            from None
    points = reader(text, file)
    return points, ('rig' if reader is _read_csv else 'image')


def _npy_header(data, file):
    """
    Return (shape, dtype) from a .npy file's header, checked before any array is made.

    :raises PlanInputError: not a .npy header, an array that is not (k, 3) real numbers, more
        than MAX_PATH_POINTS points, or more points than the file has bytes for
    """
    stream = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(stream)
        read_header = {(1, 0): np.lib.format.read_array_header_1_0,
                       (2, 0): np.lib.format.read_array_header_2_0}.get(version)
        if read_header is None:
            raise ValueError(f'format version {version[0]}.{version[1]} (1.0 or 2.0 expected)')
        shape, _, dtype = read_header(stream)
    except (ValueError, OSError, EOFError, SyntaxError) as exc:
        raise PlanInputError(f'{file}: not a readable .npy array ({exc})') from None
    if dtype.hasobject:  # np.load would refuse it too: unpickling runs code
        raise PlanInputError(f'{file}: not a readable .npy array (it holds Python objects, '
                             'which are not read: save an array of numbers)')
    if dtype.kind not in 'iuf':
        raise PlanInputError(f'{file}: expected an array of real numbers, got dtype {dtype}')
    if len(shape) != 2 or shape[1] != 3:
        raise PlanInputError(f'{file}: expected a (k, 3) array, metres, got shape {shape}')
    if shape[0] > MAX_PATH_POINTS:
        raise PlanInputError(f'{file}: its header says {shape[0]} points, more than the '
                             f'{MAX_PATH_POINTS} a path may have: resample it')
    if shape[0] * 3 * dtype.itemsize > len(data) - stream.tell():
        raise PlanInputError(f'{file}: its header says {shape[0]} points, but the file has '
                             f'{len(data) - stream.tell()} bytes of data, not '
                             f'{shape[0] * 3 * dtype.itemsize}: a truncated or damaged file')
    return shape, dtype


def _read_npy(data, file):
    _npy_header(data, file)
    try:
        array = np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise PlanInputError(f'{file}: not a readable .npy array ({exc})') from None
    if not isinstance(array, np.ndarray) or array.dtype.kind not in 'iuf':
        raise PlanInputError(f'{file}: expected an array of real numbers, got dtype '
                             f'{getattr(array, "dtype", type(array).__name__)}')
    if array.ndim != 2 or array.shape[1] != 3:
        raise PlanInputError(f'{file}: expected a (k, 3) array, metres, got shape {array.shape}')
    if len(array) == 0:
        raise PlanInputError(f'{file}: no points (an empty array)')
    return array.astype(float)


def _read_csv(text, file):
    lines = [(n, line) for n, line in enumerate(text.splitlines(), 1)
             if line.strip() and not line.lstrip().startswith('#')]
    if not lines:
        raise PlanInputError(f'{file}: empty file (only comments)')
    header_line, header = lines[0][0], _csv_fields(lines[0][1], file, lines[0][0])
    columns, scales = {}, {}
    for index, name in enumerate(header):
        match = _AXIS_COLUMN.match(name)
        if not match:
            continue
        axis, unit = match.group(1).lower(), match.group(2)
        if not unit:
            raise PlanInputError(f'{file}: line {header_line}: column {name.strip()!r} names no '
                                 f'unit: call it {axis}_m, {axis}_mm or {axis}_um')
        if unit not in UNITS_M:
            raise PlanInputError(f'{file}: line {header_line}: column {name.strip()!r}: unknown '
                                 f'unit {unit!r} (one of {", ".join(UNITS_M)})')
        if axis in columns:
            raise PlanInputError(f'{file}: line {header_line}: two {axis} columns')
        columns[axis], scales[axis] = index, UNITS_M[unit]
    missing = [a for a in 'xyz' if a not in columns]
    if missing:
        raise PlanInputError(f'{file}: line {header_line}: the header {header} has no '
                             f'{", ".join(missing)} column (name them x_mm, y_mm, z_mm or '
                             'with the unit m or um)')
    if len(lines) == 1:
        raise PlanInputError(f'{file}: no points (only a header)')
    _check_count(len(lines) - 1, file)
    points = []
    for number, line in lines[1:]:
        fields = _csv_fields(line, file, number)
        if len(fields) != len(header):
            raise PlanInputError(f'{file}: line {number} (point {len(points)}): '
                                 f'{len(fields)} fields, the header has {len(header)}')
        row = []
        for axis in 'xyz':
            value = fields[columns[axis]]
            try:
                row.append(float(value) * scales[axis])
            except ValueError:
                raise PlanInputError(f'{file}: line {number} (point {len(points)}): '
                                     f'{header[columns[axis]].strip()} {value!r} is not a '
                                     'number') from None
        points.append(row)
    return np.array(points)


def _check_count(points, file):
    """Refuse a file of more than MAX_PATH_POINTS points before they are parsed."""
    if points > MAX_PATH_POINTS:
        raise PlanInputError(f'{file}: {points} points, more than the {MAX_PATH_POINTS} a '
                             'path may have: resample it')


def _csv_fields(line, file, number):
    try:
        return next(csv.reader([line], strict=True))
    except csv.Error as exc:
        raise PlanInputError(f'{file}: line {number}: malformed CSV ({exc})') from None


def _read_markups(text, file):
    try:
        document = json.loads(text)
    except json.JSONDecodeError as exc:
        raise PlanInputError(f'{file}: not valid JSON: {exc.msg} at line {exc.lineno} column '
                             f'{exc.colno}') from None
    except RecursionError:
        raise PlanInputError(f'{file}: not valid JSON: nested too deeply') from None
    if not isinstance(document, dict) or not isinstance(document.get('markups'), list):
        raise PlanInputError(f'{file}: not a Slicer markups file (no markups list)')
    if not document['markups']:
        raise PlanInputError(f'{file}: markups: empty list, no markup')
    markup = document['markups'][0]  # Slicer loads only the first
    where = f'{file}: markups[0]'
    if not isinstance(markup, dict):
        raise PlanInputError(f'{where}: expected an object, got {type(markup).__name__}')
    kind = markup.get('type')
    if kind not in SLICER_TYPES:
        raise PlanInputError(f'{where}.type: {kind!r} is not a path: give a Curve or a point '
                             'list (Fiducial)')
    system = markup.get('coordinateSystem', 'LPS')
    if system not in ('LPS', 'RAS'):
        raise PlanInputError(f'{where}.coordinateSystem: unknown coordinate system {system!r} '
                             '(LPS or RAS)')
    units = markup.get('coordinateUnits', 'mm')
    unit = units
    if isinstance(units, list) and len(units) == 3 and units[1] == 'UCUM':
        unit = units[0]  # a coded entry: [code value, coding scheme, meaning]
    if not isinstance(unit, str) or unit not in UNITS_M:
        raise PlanInputError(f'{where}.coordinateUnits: unknown unit {units!r} (one of '
                             f'{", ".join(UNITS_M)}, or a UCUM coded entry of one)')
    raw = markup.get('controlPoints', [])
    if not isinstance(raw, list):
        raise PlanInputError(f'{where}.controlPoints: expected a list, got '
                             f'{type(raw).__name__}')
    if not raw:
        raise PlanInputError(f'{where}.controlPoints: no points')
    _check_count(len(raw), file)
    points = []
    for i, point in enumerate(raw):
        at = f'{where}.controlPoints[{i}]'
        if not isinstance(point, dict):
            raise PlanInputError(f'{at}: expected an object, got {type(point).__name__}')
        label = f' ({point["label"]!r})' if isinstance(point.get('label'), str) else ''
        status = point.get('positionStatus', 'defined')
        position = point.get('position')
        if status != 'defined' or position in (None, ''):
            raise PlanInputError(f'{at}{label}: the position of the point is undefined '
                                 f'(positionStatus {status!r}): place it in Slicer or delete '
                                 'it')
        if (not isinstance(position, list) or len(position) != 3
                or any(isinstance(v, bool) or not isinstance(v, (int, float))
                       for v in position)):
            raise PlanInputError(f'{at}{label}.position: expected three numbers, got '
                                 f'{position!r}')
        points.append([float(v) for v in position])
    return _slicer_to_rig_units(np.array(points), system, UNITS_M[unit])


def _read_fcsv(text, file):
    system = 'LPS'  # what Slicer assumes of a file without the line
    points = []
    lines = text.splitlines()
    _check_count(sum(1 for line in lines if line.strip() and not line.lstrip().startswith('#')),
                 file)
    for number, line in enumerate(lines, 1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith('#'):
            name, _, value = stripped[1:].partition('=')
            name, value = name.strip(), value.strip()
            if name == 'CoordinateSystem':
                if value not in SLICER_SYSTEMS:
                    raise PlanInputError(f'{file}: line {number}: unknown coordinate system '
                                         f'{value!r} (LPS or RAS; in older files 0 = RAS, '
                                         '1 = LPS)')
                system = SLICER_SYSTEMS[value]
            elif name == 'columns':
                columns = [c.strip() for c in value.split(',')]
                if columns[:4] != ['id', 'x', 'y', 'z']:
                    raise PlanInputError(f'{file}: line {number}: columns {value!r}: Slicer '
                                         'reads id,x,y,z first whatever this line says')
            continue
        fields = _csv_fields(line, file, number)
        where = f'{file}: line {number} (point {len(points)})'
        if len(fields) < 4:
            raise PlanInputError(f'{where}: expected id,x,y,z,..., got {len(fields)} field(s)')
        try:
            xyz = [float(v) for v in fields[1:4]]
        except ValueError:
            raise PlanInputError(f'{where}: x, y, z {fields[1:4]} are not numbers') from None
        if len(fields) > FCSV_POSITION_STATUS and \
                fields[FCSV_POSITION_STATUS].strip() not in ('', '2'):
            raise PlanInputError(f'{where}: the position of the point is undefined '
                                 f'(positionStatus {fields[FCSV_POSITION_STATUS].strip()}; 2 '
                                 'is defined): place it in Slicer or delete it')
        points.append(xyz)
    if not points:
        raise PlanInputError(f'{file}: no points (only comments)')
    return _slicer_to_rig_units(np.array(points), system, 1e-3)


def _slicer_to_rig_units(points, system, scale):
    """Return Slicer points as RAS metres."""
    points = points * scale
    if system == 'LPS':
        points[:, :2] *= -1.0
    return points


def check_followable(path, link_length_m, start_direction=None):
    """
    Refuse a path that turns more than MAX_TURN_DEG between consecutive chords a link long.

    The chords from s - h to s and from s to s + h are the two links either side of a joint
    at arc length s; as the tentacle goes in, a joint passes every s. Checked at every path
    point, every point plus or minus h and every h / 8 in between; and, at the clamp, the
    first chord against the insertion direction.

    :param path: a Path
    :param link_length_m: h, m: the longest link of the chain that follows the path
    :param start_direction: (3,) the base insertion direction, or None: not checked
    :raises PlanInputError: naming the arc length, the nearest path point, the turn and the
        radius of curvature that corresponds to the limit
    """
    h = float(link_length_m)
    length = path.length_m
    if not h > 0:
        return
    if start_direction is not None:
        first = path.at(min(h, length)) - path.points_m[0]
        turn = _angles_deg(np.asarray(start_direction, dtype=float)[None, :], first[None, :])[0]
        if turn > MAX_TURN_DEG:
            raise PlanInputError(
                f'{path.source}: point 0: the path leaves the insertion point {turn:.1f} '
                f'degrees off the insertion direction (over the first link, '
                f'{h * 1e3:.3g} mm), more than the {MAX_TURN_DEG:g} the clamp joint takes')
    if length < 2 * h:
        return
    arcs = path.arc_lengths_m
    grid = np.concatenate([arcs, arcs - h, arcs + h,
                           np.linspace(h, length - h, math.ceil((length - 2 * h) / (h / 8)) + 1)])
    grid = np.unique(grid[(grid >= h) & (grid <= length - h)])
    before, here, after = path.at(grid - h), path.at(grid), path.at(np.minimum(grid + h, length))
    turns = _angles_deg(here - before, after - here)
    worst = int(np.argmax(turns))
    if turns[worst] > MAX_TURN_DEG:
        s = grid[worst]
        near = int(np.argmin(np.abs(arcs - s)))
        radius = 3 * h / (2 * math.pi)
        raise PlanInputError(
            f'{path.source}: point {near}: the path turns {turns[worst]:.1f} degrees within '
            f'two links ({h * 1e3:.3g} mm each) at {s * 1e3:.2f} mm along it, more than the '
            f'{MAX_TURN_DEG:g} the links of the model take before they fold onto each other (on '
            f'an arc: a radius of curvature under {radius * 1e3:.3g} mm)')


def targets(path, chain, inserted_m):
    """
    Return the follow-the-leader target of an insertion step: joints and tip (n + 1, 3), m.

    With the inserted length l of a rod of length L, link i's proximal joint (material
    coordinate chain.s_start_m[i]) belongs at arc length s_start - (L - l) along the path and
    the tip at l: the body that has gone in lies on the path behind its tip. The clamp joint
    is at arc length 0.

    :param path: a Path in the rig frame
    :param chain: tentacle_model.chain.Chain at inserted_m (chain.discretise)
    :param inserted_m: the inserted length l, m
    :raises PlanInputError: the path is shorter than l
    :raises ValueError: a chain of another inserted length
    """
    inserted = float(inserted_m)
    lengths = np.asarray(chain.lengths_m, dtype=float)
    starts = np.asarray(chain.s_start_m, dtype=float)
    # discretise drops a partial link shorter than 1e-6 of its full length.
    slack = 1e-6 * (lengths.max() if len(lengths) else 0.0) + 1e-12
    if not np.isfinite(inserted) or abs(lengths.sum() - inserted) > slack:
        raise ValueError(f'the chain has {lengths.sum():g} m free, not the {inserted_m} m '
                         'inserted')
    if inserted > path.length_m * (1 + 1e-9):
        raise PlanInputError(f'{path.source}: the path is {path.length_m * 1e3:.4g} mm long, '
                             f'shorter than the {inserted * 1e3:.4g} mm inserted')
    if not len(lengths):
        return path.at(np.zeros(1))
    total = starts[-1] + lengths[-1]
    arcs = np.append(starts - (total - inserted), min(inserted, path.length_m))
    arcs[0] = 0.0
    return path.at(np.clip(arcs, 0.0, path.length_m))


def shape_error(points_m, path, inserted_m, samples=SHAPE_SAMPLES):
    """
    Return (shape RMS, tip error), m: the project's shape error (DESIGN.md).

    The RMS of the distance between the inserted body (the polyline of its joints and tip)
    and the path at equal arc lengths from the insertion point, at SHAPE_SAMPLES points or
    more; and the tip's distance from the path at the inserted length.
    """
    points = np.asarray(points_m, dtype=float)
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    along = np.concatenate([[0.0], np.cumsum(steps)])
    s = np.linspace(0.0, min(inserted_m, along[-1]), max(samples, len(points)))
    body = np.column_stack([np.interp(s, along, points[:, axis]) for axis in range(3)])
    distances = np.linalg.norm(body - path.at(s), axis=1)
    tip = float(np.linalg.norm(points[-1] - path.at(min(inserted_m, path.length_m))))
    return float(np.sqrt(np.mean(distances ** 2))), tip
