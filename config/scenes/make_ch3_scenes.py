#!/usr/bin/env python3
"""
Write the chapter 3 scenes ch3_a.yaml .. ch3_d.yaml (reconstructions, not the thesis data).

Thesis section 3.4 gives the tentacle (config/tentacles/tentacle_chapter3.yaml), four
insertion steps of 14 mm and four planar obstacle courses in Figs. 3.2-3.6, drawn but not
tabulated: "the sample path was generated considering four segments of equal length 14 mm".
Each path here is such a polyline, given by the heading of each 14 mm segment from the
insertion direction (in the thesis frame: inserted along -y, positive towards +x; no turn
over 15 deg, where the thesis saw its rigid-link model break down), extended 2 mm straight
past the tip. Each obstacle (a grey circle) is given by where it stands beside the path: the
arc length s of the path point it faces, the side (+1: the +x side of the path's tangent),
and its radius; its surface is 0.5 mm from the body's when the body lies on the path.

- A: straight for a link, then a bend to +x that tightens to the tip (J-shaped): a
  tip-driven catheter bends most at its base and meets the obstacle inside the bend.
- B: one even arc to +x (14 deg per joint).
- C: a bend to +x that reverses mid-length (S-shaped: the thesis' hard case).
- D: a bend to -x that relaxes towards the tip.

Run from anywhere: python3 config/scenes/make_ch3_scenes.py (rewrites the four files).
"""

import math
import pathlib

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
LINK_M = 0.014
BODY_RADIUS_M = 0.001
EXTRA_M = 0.002         # straight past the tip: the deepest step's tip stays on the path
SAMPLE_M = 0.0005       # the path's points, every 0.5 mm
DOWN, ACROSS = np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.0, 0.0])
GAP_M = 0.0005          # every obstacle's surface from the body's on the path
SCENES = {  # name: (what, segment headings in deg, [(s m, side, radius m)])
    'ch3_a': ('J-shaped: straight for a link, then a bend to +x tightening to the tip',
              (0.0, 3.0, 12.0, 27.0),
              [(0.035, +1, 0.002), (0.030, -1, 0.002),
               (0.050, -1, 0.0025)]),
    'ch3_b': ('one arc to +x, 14 deg per joint', (7.0, 21.0, 35.0, 49.0),
              [(0.030, +1, 0.002), (0.040, -1, 0.002),
               (0.052, +1, 0.002)]),
    'ch3_c': ('S-shaped: to +x, reversing mid-length', (12.0, 22.0, 18.0, 4.0),
              [(0.022, +1, 0.002), (0.034, -1, 0.002),
               (0.050, +1, 0.002)]),
    'ch3_d': ('to -x, relaxing towards the tip', (-14.0, -26.0, -33.0, -36.0),
              [(0.026, -1, 0.002), (0.036, +1, 0.002),
               (0.048, -1, 0.002)]),
}


def direction(heading_deg):
    """Return the unit vector heading_deg off the insertion axis, positive towards +x."""
    h = math.radians(heading_deg)
    return math.cos(h) * DOWN + math.sin(h) * ACROSS


def centreline(headings_deg):
    """Return the path's points, every SAMPLE_M along the polyline, and its vertices, m."""
    vertices = [np.zeros(3)]
    for h in headings_deg:
        vertices.append(vertices[-1] + LINK_M * direction(h))
    vertices.append(vertices[-1] + EXTRA_M * direction(headings_deg[-1]))
    vertices = np.array(vertices)
    points = [vertices[0]]
    for a, b in zip(vertices[:-1], vertices[1:]):
        count = round(np.linalg.norm(b - a) / SAMPLE_M)
        points += [a + (b - a) * t for t in np.arange(1, count + 1) / count]
    return np.array(points), vertices


def obstacle_centre(vertices, s_m, side, gap_m, radius_m):
    """Return the centre of an obstacle facing the path at arc length s, m."""
    segment = min(int(s_m // LINK_M), len(vertices) - 2)
    a, b = vertices[segment], vertices[segment + 1]
    tangent = (b - a) / np.linalg.norm(b - a)
    normal = np.array([-tangent[1], tangent[0], 0.0])  # +x side of a path going down -y
    on_path = a + tangent * (s_m - segment * LINK_M)
    return on_path + side * normal * (BODY_RADIUS_M + gap_m + radius_m)


def document(name, what, headings, points, obstacles):
    """Return the scene file's text."""
    rows = '\n'.join(f'  - [{x:.9f}, {y:.9f}, 0.0]' for x, y, _ in points)
    circles = '\n'.join(f'  - {{centre_m: [{x:.6f}, {y:.6f}, 0.0], radius_m: {r}}}'
                        for (x, y, _), r in obstacles)
    return f"""# {name}: thesis chapter 3 (section 3.4, Figs. 3.2-3.6), a reconstruction from
# the text, not the thesis data (written by make_ch3_scenes.py). The chapter 3 tentacle
# (four homogenised 14 mm Ecoflex/NdFeB segments), four insertion steps of 14 mm, planar
# joints, gravity along the insertion as in eq. 3.3.
# Path: four 14 mm segments with headings {headings} deg: {what}.
name: {name}
tentacle: ../tentacles/tentacle_chapter3.yaml
path:
  points_m:
{rows}
insertion_steps_m: [0.014, 0.028, 0.042, 0.056]
coil: {{max_field_t: 0.02}}
obstacles:
{circles}
model: {{dof: 1, sublinks: 1, gravity_m_s2: [0.0, -9.81, 0.0], dipoles: false}}
magnetisation: {{planar: true}}
"""


def main():
    """Write the four scenes next to this file."""
    for name, (what, headings, placed) in SCENES.items():
        points, vertices = centreline(headings)
        obstacles = [(obstacle_centre(vertices, s, side, GAP_M, r), r) for s, side, r in placed]
        text = document(name, what, ', '.join(f'{h:g}' for h in headings), points, obstacles)
        (HERE / f'{name}.yaml').write_text(text)
        print(f'wrote {HERE / name}.yaml')


if __name__ == '__main__':
    main()
