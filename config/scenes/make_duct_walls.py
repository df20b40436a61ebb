#!/usr/bin/env python3
"""
Give the duct scenes their phantom: the channel's two walls along each path, in its plane.

Thesis 5.3.2 builds the phantom from the duct network scaled so that the bile duct's largest
internal diameter is 7 mm (its reference [25]), with a major papilla of at least 2.6 mm
([26]), projected onto a plane and extruded 20 mm: an open channel. Here:

- bile_duct: a 7 mm channel (the thesis' figure, taken all along the duct).
- pancreatic_duct: a 3.5 mm channel. The thesis gives no width for the pancreatic duct; in
  normal anatomy the main pancreatic duct is about half as wide as the common bile duct (up
  to about 3.5 mm in the head of the pancreas against 7 mm), so half the bile duct's width.
  An assumption, not a thesis figure: a lab with its own phantom measures its channel.

The papilla is where the inserter's sleeve (2.5 mm inside, thesis 5.3.3) holds the base: the
walls start at the path's start, one on each side, WALL_SPACING_M apart along the path, every
point HALF the width from the centreline in the path's plane (a point nearer the centreline
than that, inside a bend tighter than the half width, is left out). The body's gap to a wall
is its gap to the wall's nearest point (clearance.py): with points 0.25 mm apart, at most
0.03 mm more than to the wall's line at a 0.25 mm gap.

Run from anywhere: python3 config/scenes/make_duct_walls.py (rewrites the obstacles block of
both scene files, nothing else).
"""

import pathlib
import re

import numpy as np
import yaml

HERE = pathlib.Path(__file__).resolve().parent
WALL_SPACING_M = 2.5e-4
WIDTHS_M = {'bile_duct': 7e-3, 'pancreatic_duct': 3.5e-3}
SOURCES = {'bile_duct': 'the thesis: 5.3.2, the bile duct at most 7 mm inside',
           'pancreatic_duct': 'assumed: half the bile duct (no thesis figure), '
                              'see make_duct_walls.py'}


def walls(points_m, width_m, spacing_m=WALL_SPACING_M):
    """Return the (left, right) wall points (k, 3) of a planar path, m."""
    points = np.asarray(points_m, dtype=float)
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    arcs = np.concatenate([[0.0], np.cumsum(steps)])
    s = np.arange(0.0, arcs[-1] + 1e-12, spacing_m)
    centre = np.column_stack([np.interp(s, arcs, points[:, i]) for i in range(3)])
    segment = np.clip(np.searchsorted(arcs, s, side='right') - 1, 0, len(steps) - 1)
    tangent = np.diff(points, axis=0)[segment] / steps[segment, None]
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0], np.zeros(len(s))])
    out = []
    for side in (1.0, -1.0):
        wall = centre + side * width_m / 2 * normal
        # Inside a bend tighter than the half width the offset folds over: drop those points.
        nearest = np.min(np.linalg.norm(wall[:, None, :] - centre[None], axis=2), axis=1)
        out.append(wall[nearest > width_m / 2 - 1e-9])
    return out


def block(name, width_m, points_m):
    """Return a duct's obstacles block for its scene file, YAML text."""
    lines = [f'# The phantom (make_duct_walls.py): an open channel {width_m * 1e3:g} mm wide, '
             f'{SOURCES[name]}.', 'obstacles:', '  walls:']
    for wall in walls(points_m, width_m):
        lines.append('  - points_m:')
        lines += [f'    - [{x:.6f}, {y:.6f}, {z:.6f}]' for x, y, z in wall]
    return '\n'.join(lines) + '\n'


def main():
    """Rewrite each duct scene's obstacles block."""
    for name, width_m in WIDTHS_M.items():
        path = HERE / f'{name}.yaml'
        text = path.read_text()
        doc = yaml.safe_load(text)
        if any(p[2] != 0.0 for p in doc['path']['points_m']):
            raise SystemExit(f'{path}: the path is not in the z = 0 plane')
        text = re.sub(r'# The phantom \(make_duct_walls\.py\).*\nobstacles:\n(  .*\n)*', '',
                      text)
        anchor = re.search(r'^magnetisation:.*\n', text, flags=re.M)
        text = text[:anchor.end()] + block(name, width_m, doc['path']['points_m']) + \
            text[anchor.end():]
        path.write_text(text)
        print(f'{path.name}: {width_m * 1e3:g} mm channel')


if __name__ == '__main__':
    main()
