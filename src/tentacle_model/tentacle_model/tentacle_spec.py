"""
A tentacle described in YAML (SI units), validated into plain dataclasses.

Format (see config/tentacles/cantilever.yaml)::

    name: cantilever
    base:                          # the insertion point: the rod is clamped here
      position_m: [0.0, 0.0, 0.0]
      direction: [1.0, 0.0, 0.0]   # insertion direction: the link x axis at rest
      normal: [0.0, 1.0, 0.0]      # link y axis at rest; planar bending is in direction-normal
    segments:                      # proximal (base side) to distal (tip)
      - length_m: 0.020
        section: {diameter_m: 0.002}          # or {width_m: ..., height_m: ...}
        youngs_modulus_pa: 1.0e5              # or {bend_1: ..., bend_2: ..., twist: ...}
        density_kg_m3: 1400.0
        magnetisation: {remanence_t: 0.107, direction: [1.0, 0.0, 0.0]}  # link frame; or none
        reinforcement:                        # optional: fibres around the axis (chapter 4)
          helices: 2                          # in pairs; or braid: K (yarns, interlaced)
          angle_deg: 85.0                     # the fibres' angle to the axis
          fibre_modulus_pa: 2.4e+9
          fibre_diameter_m: 0.0004
          radius_m: 0.00225                   # of the helix the fibres' centrelines lie on
    backbone:                      # optional stiffening backbone (thesis chapter 6)
      youngs_modulus_pa: 5.0e10
      diameter_m: 0.0005           # of each rod
      count: 2                     # rods (default 1)

``bend_1`` is bending in the base plane (about the link z axis), ``bend_2`` out of it (about
link y), ``twist`` about the link axis (a pseudo-modulus with the polar moment, as thesis
Table 5.1: a braid gives 500 / 500 / 10,000 kPa against 100 kPa unreinforced). A rectangular
section has ``width_m`` along link y and ``height_m`` along link z. A reinforced segment's
``youngs_modulus_pa`` is its matrix's; its pseudo-moduli add what the fibres carry
(reinforcement.py: the closed-form estimate, stated there).
"""

from dataclasses import dataclass, replace
import math
import pathlib

import numpy as np
from tentacle_model.reinforcement import KINDS, pseudo_moduli, Reinforcement
from tentacle_model.user_files import FieldReader, load_yaml, read_capped
import yaml

MU0 = 4e-7 * math.pi  # vacuum permeability, T m / A
MAX_FILE_BYTES = 64 * 1024
"""
The largest tentacle file load_tentacle reads, bytes; it reads at most one byte more.

Eleven times the largest shipped file (vsr_chapter6.yaml, 24 segments, 5.6 kB): room for some
280 segments written out as fully. PyYAML's pure-Python parser takes up to 1 s here on a file
of this size (64 KiB of nested brackets or a list of numbers), 16 s on 1 MiB.
"""


class SpecError(ValueError):
    """A tentacle file is malformed; the message names the file and the field."""


@dataclass(frozen=True)
class Segment:
    """One segment: geometry, stiffness and magnetisation, SI units."""

    length_m: float
    area_m2: float
    second_moment_m4: tuple      # (I about link y, I about link z), m^4
    polar_moment_m4: float       # J, m^4
    modulus_pa: tuple            # (bend_1 about z, bend_2 about y, twist), Pa: pseudo-moduli
    density_kg_m3: float
    magnetisation_a_per_m: np.ndarray  # (3,) M = Br / mu0 along the direction, link frame
    radius_m: float = 0.0        # the section's farthest edge from the axis (clearances), m
    width_m: float = 0.0         # its extent along link y, in the base plane (a camera), m
    reinforcement: Reinforcement | None = None
    matrix_modulus_pa: tuple = None   # modulus_pa without the reinforcement, Pa

    @property
    def bend_stiffness_n_m2(self):
        """Return (EI in the base plane, EI out of it, GJ-like twist stiffness), N m^2."""
        return (self.modulus_pa[0] * self.second_moment_m4[1],
                self.modulus_pa[1] * self.second_moment_m4[0],
                self.modulus_pa[2] * self.polar_moment_m4)


@dataclass(frozen=True)
class Backbone:
    """A stiff backbone inside the proximal rod: its bending stiffness EI, N m^2."""

    stiffness_n_m2: float


@dataclass(frozen=True)
class TentacleSpec:
    """A whole tentacle: base pose and segments from base to tip."""

    name: str
    base_position_m: np.ndarray   # (3,)
    base_rotation: np.ndarray     # (3, 3) columns: link x (direction), y (normal), z
    segments: tuple
    backbone: Backbone | None = None

    @property
    def length_m(self):
        """Return the total rod length, m."""
        return sum(s.length_m for s in self.segments)


def _segment(read, raw, where):
    raw = read.mapping(raw, where, {'length_m', 'section', 'youngs_modulus_pa',
                                    'density_kg_m3', 'magnetisation', 'reinforcement'},
                       ('length_m', 'section', 'youngs_modulus_pa', 'density_kg_m3'))
    length = read.number(raw['length_m'], f'{where}.length_m')
    section = read.mapping(raw['section'], f'{where}.section',
                           {'diameter_m', 'width_m', 'height_m'})
    if 'diameter_m' in section:
        if len(section) != 1:
            read.fail(f'{where}.section', 'give diameter_m, or width_m and height_m')
        d = read.number(section['diameter_m'], f'{where}.section.diameter_m')
        area, i_y, i_z, polar = math.pi * d * d / 4, math.pi * d ** 4 / 64, \
            math.pi * d ** 4 / 64, math.pi * d ** 4 / 32
        radius, width = d / 2, d
    else:
        section = read.mapping(section, f'{where}.section', {'width_m', 'height_m'},
                               ('width_m', 'height_m'))
        w = read.number(section['width_m'], f'{where}.section.width_m')
        h = read.number(section['height_m'], f'{where}.section.height_m')
        area, i_y, i_z = w * h, w * h ** 3 / 12, h * w ** 3 / 12
        polar = i_y + i_z
        radius, width = math.hypot(w, h) / 2, w
    modulus = raw['youngs_modulus_pa']
    if isinstance(modulus, dict):
        modulus = read.mapping(modulus, f'{where}.youngs_modulus_pa',
                               {'bend_1', 'bend_2', 'twist'}, ('bend_1', 'bend_2', 'twist'))
        moduli = tuple(read.number(modulus[k], f'{where}.youngs_modulus_pa.{k}')
                       for k in ('bend_1', 'bend_2', 'twist'))
    else:
        moduli = (read.number(modulus, f'{where}.youngs_modulus_pa'),) * 3
    density = read.number(raw['density_kg_m3'], f'{where}.density_kg_m3')
    magnetisation = np.zeros(3)
    mag = raw.get('magnetisation')
    if mag is not None and mag != 'none':
        mag = read.mapping(mag, f'{where}.magnetisation', {'remanence_t', 'direction'},
                           ('remanence_t', 'direction'))
        br = read.number(mag['remanence_t'], f'{where}.magnetisation.remanence_t',
                         allow_zero=True)
        magnetisation = br / MU0 * read.vector(mag['direction'],
                                               f'{where}.magnetisation.direction', unit=True)
    fibres = None
    if raw.get('reinforcement') is not None:
        # the largest circle inside the section: the fibres lie within it
        fibres = _reinforcement(read, raw['reinforcement'], f'{where}.reinforcement',
                                d / 2 if 'diameter_m' in section else min(w, h) / 2)
    return reinforced(Segment(length, area, (i_y, i_z), polar, moduli, density, magnetisation,
                              radius, width), moduli, fibres)


def reinforced(segment, matrix_pa, reinforcement):
    """Return segment with matrix moduli matrix_pa (bend_1, bend_2, twist) and reinforcement."""
    return replace(segment, reinforcement=reinforcement, matrix_modulus_pa=tuple(matrix_pa),
                   modulus_pa=pseudo_moduli(matrix_pa, segment.second_moment_m4,
                                            segment.polar_moment_m4, reinforcement))


def _reinforcement(read, raw, where, inside_m):
    """Return the Reinforcement of a segment's reinforcement block, its fibres inside_m."""
    keys = ('angle_deg', 'fibre_modulus_pa', 'fibre_diameter_m', 'radius_m')
    raw = read.mapping(raw, where, {*KINDS, *keys}, keys)
    kinds = [k for k in KINDS if k in raw]
    if len(kinds) != 1:
        read.fail(where, 'give helices: N (bonded layers) or braid: N (interlaced yarns)')
    count = raw[kinds[0]]
    if isinstance(count, bool) or not isinstance(count, int) or count < 2 or count % 2:
        # one hand alone would couple twist to stretch: fibres come in left and right pairs
        read.fail(f'{where}.{kinds[0]}', f'{count!r} is not an even whole number from 2 '
                                         '(fibres come in left- and right-handed pairs)')
    angle = read.number(raw['angle_deg'], f'{where}.angle_deg', allow_zero=True)
    if angle > 90:
        read.fail(f'{where}.angle_deg', f'{angle:g} is more than 90 (the angle to the axis)')
    d = read.number(raw['fibre_diameter_m'], f'{where}.fibre_diameter_m')
    radius = read.number(raw['radius_m'], f'{where}.radius_m')
    if radius + d / 2 > inside_m * (1 + 1e-9):
        read.fail(f'{where}.radius_m', f'{radius:g} m with fibres {d:g} m thick is outside '
                                       f'the section ({inside_m:g} m from the axis)')
    return Reinforcement(kinds[0], count, math.radians(angle),
                         read.number(raw['fibre_modulus_pa'], f'{where}.fibre_modulus_pa'),
                         d, radius)


def parse_tentacle(document, source='<tentacle>'):
    """
    Return a TentacleSpec from a parsed YAML document.

    :raises SpecError: naming the source and the offending field
    """
    read = FieldReader(source, SpecError)
    doc = read.mapping(document, 'top level', {'name', 'base', 'segments', 'backbone'},
                       ('segments',))
    base = read.mapping(doc.get('base', {}), 'base', {'position_m', 'direction', 'normal'})
    position = read.vector(base.get('position_m', [0.0, 0.0, 0.0]), 'base.position_m')
    direction = read.vector(base.get('direction', [1.0, 0.0, 0.0]), 'base.direction', unit=True)
    normal = read.vector(base.get('normal', [0.0, 1.0, 0.0]), 'base.normal', unit=True)
    normal = normal - direction * float(direction @ normal)
    if np.linalg.norm(normal) < 1e-9:
        read.fail('base.normal', 'must not be parallel to base.direction')
    normal /= np.linalg.norm(normal)
    rotation = np.column_stack([direction, normal, np.cross(direction, normal)])
    segments = doc['segments']
    if not isinstance(segments, list) or not segments:
        read.fail('segments', 'expected a non-empty list')
    segments = tuple(_segment(read, raw, f'segments[{i}]') for i, raw in enumerate(segments))
    backbone = None
    if doc.get('backbone') is not None:
        raw = read.mapping(doc['backbone'], 'backbone',
                           {'youngs_modulus_pa', 'diameter_m', 'count'},
                           ('youngs_modulus_pa', 'diameter_m'))
        e = read.number(raw['youngs_modulus_pa'], 'backbone.youngs_modulus_pa')
        d = read.number(raw['diameter_m'], 'backbone.diameter_m')
        count = read.number(raw.get('count', 1), 'backbone.count')
        if count != int(count):
            read.fail('backbone.count', f'{count:g} is not a whole number of rods')
        # Thesis eq. 6.4: n rods of radius r, I = n pi r^4 / 4 (bending about their centres).
        backbone = Backbone(e * count * math.pi * d ** 4 / 64)
    name = doc.get('name', pathlib.Path(str(source)).stem)
    if not isinstance(name, str) or not name.strip():
        read.fail('name', f'expected a non-empty string, got {name!r}')
    return TentacleSpec(name, position, rotation, segments, backbone)


def load_tentacle(path):
    """
    Read and validate a tentacle YAML file.

    :raises SpecError: unreadable, not a regular file, larger than MAX_FILE_BYTES, not UTF-8
        text, not YAML, a key given twice, or a field that is missing, unknown or invalid
    """
    data = read_capped(path, MAX_FILE_BYTES, SpecError, 'a tentacle file')
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise SpecError(f'{path}: not UTF-8 text ({exc.reason} at byte {exc.start})') from None
    try:
        document = load_yaml(text)
    except yaml.YAMLError as exc:  # a repeated key too
        raise SpecError(f'{path}: not valid YAML: {exc}') from None
    except RecursionError:  # PyYAML's composer recurses once per level of nesting
        raise SpecError(f'{path}: not valid YAML: nested too deeply') from None
    return parse_tentacle(document, path)
