"""
Writing schedule files (DESIGN.md, "Scenes and schedules") and the plan's terminal summary.

``write_schedule(out_dir, result)`` writes DIR/schedule.yaml, self-contained: the planned
tentacle (the scene's tentacle file with every magnetised segment's direction replaced by
the planned one), the planning model's settings, the magnetisation also as angles for the
magnetising tray, the path, and per step the insertion, field, predicted centreline, shape
RMS, tip error and stability (every dense playback step when the scene asks for them, key
steps marked), the robustness figures and the flags; and DIR/plan.png (plan_plot.py).
schedule_file.py reads it back. Shape errors are the project's (paths.shape_error).

A path of more than SCHEDULE_PATH_POINTS points goes into the schedule (and the picture)
thinned: every k-th point and its last, k the smallest that leaves at most that many, and
``path_thinned: {of_points: N, every: k}`` says so (the plan itself follows every point).
A folder never mixes two runs: each file is written under a temporary name and renamed into
place, and the previous run's picture is removed before the new schedule goes in.
"""

import math
import os
import pathlib

import numpy as np
from tentacle_model.tentacle_spec import MAX_FILE_BYTES as MAX_TENTACLE_BYTES
from tentacle_model.user_files import load_yaml, read_capped
from tentacle_planner.errors import PlanInputError
from tentacle_planner.planner import magnetisation_angles_deg, shape_rms, step_clearance
from tentacle_planner.robustness import ON_THE_RIG
from tentacle_planner.schedule_file import FORMAT
import yaml

SCHEDULE_PATH_POINTS = 2000  # a path's points written out; a million took a minute to write
OUTPUTS = ('schedule.yaml', 'plan.png')  # what a run writes into its folder


def thinned(points, limit=SCHEDULE_PATH_POINTS):
    """Return (points, k): every k-th of points (k, 3) and the last, at most limit of them."""
    count = len(points)
    if count <= limit:
        return points, 1
    every = math.ceil((count - 1) / (limit - 2))
    index = np.arange(0, count, every)
    return points[np.append(index, count - 1) if index[-1] != count - 1 else index], every


def _floats(array, digits=9):
    return [[round(float(v), digits) for v in row] for row in np.asarray(array)]


def planned_tentacle(result):
    """Return the tentacle file's document with the planned magnetisation directions."""
    # The file the scene was validated from, read as strictly again (tentacle_spec).
    data = read_capped(result.scene.tentacle_file, MAX_TENTACLE_BYTES, PlanInputError,
                       'a tentacle file')
    document = load_yaml(data.decode('utf-8'))
    for segment, direction in zip(document['segments'], result.plan.directions):
        if segment.get('magnetisation') and np.any(direction):
            segment['magnetisation']['direction'] = [round(float(v), 9) for v in direction]
    return document


def schedule_document(result):
    """Return the schedule as a plain document (the YAML's content)."""
    scene, plan = result.scene, result.plan
    model = result.planning_model or scene.model
    key = {round(s.inserted_m, 12) for s in plan.steps}
    played = result.playback_steps or plan.steps
    steps = []
    for step in played:
        rms, tip = scene.shape_error(step)
        steps.append({'insertion_m': round(step.inserted_m, 9),
                      'key': round(step.inserted_m, 12) in key,
                      'field_t': [round(float(v), 9) for v in step.field_t],
                      'predicted_centreline_m': _floats(step.points_m),
                      'shape_rms_m': round(rms, 9), 'tip_error_m': round(tip, 9),
                      'stability': float(f'{step.stability:.6g}')})
        if scene.backbone_steps_m:
            steps[-1]['backbone_m'] = round(step.backbone_m, 9)
        if scene.obstacles or scene.walls:
            steps[-1]['clearance_m'] = round(step_clearance(scene, step)[0], 9)
    angles = magnetisation_angles_deg(plan.directions)
    magnetised = [i for i, d in enumerate(plan.directions) if np.any(d)]
    path, every = thinned(scene.path.points_m)

    def robustness(rows):
        return [{'model': name, 'shape_rms_m': round(total, 9),
                 'per_step_m': [round(v, 9) for v in per_step],
                 'contact_depth_m': round(depth, 9)} for name, per_step, total, depth in rows]
    document = {
        'format': FORMAT,
        'scene': {'name': scene.name, 'sha256': scene.sha256},
        'tentacle': planned_tentacle(result),
        'model': {'dof': model.dof, 'sublinks': model.sublinks,
                  'gravity_m_s2': [float(g) for g in model.gravity_m_s2],
                  'dipoles': model.dipoles},
        'magnetisation_deg': [{'segment': i + 1, 'azimuth_deg': round(float(angles[i, 0]), 3),
                               'elevation_deg': round(float(angles[i, 1]), 3)}
                              for i in magnetised],
        'path_m': _floats(path),
        **({'path_thinned': {'of_points': len(scene.path.points_m), 'every': every}}
           if every > 1 else {}),
        'steps': steps,
        'robustness': {'nominal_plan': robustness(result.robustness)},
        'flags': list(result.flags),
        'interrupted': bool(result.interrupted),
    }
    if result.robust_plan is not None:
        document['robustness']['robust_plan'] = robustness(result.robust_robustness)
    if result.verification:
        planned = shape_rms(scene, plan.steps)
        document['verification'] = [{'model': what, 'shape_rms_m': round(rms, 9),
                                     'change_m': round(rms - planned, 9)}
                                    for what, rms in result.verification]
    return document


def write_schedule(out_dir, result):
    """Write DIR/schedule.yaml and DIR/plan.png; return the schedule's path."""
    from tentacle_planner.plan_plot import write_plot  # matplotlib: only when drawing
    path = write_schedule_file(out_dir, result)
    write_plot(out_dir, result)
    return path


def write_schedule_file(out_dir, result):
    """
    Write DIR/schedule.yaml, replacing any previous run's outputs; return its path.

    Written under a temporary name and renamed: an interruption leaves the previous run's
    files as they were, or the new schedule alone (the previous picture removed first).
    """
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    text = yaml.safe_dump(schedule_document(result), sort_keys=False)
    path = out / 'schedule.yaml'
    replace_file(path, lambda temporary: temporary.write_text(text))
    return path


def clear_outputs(out_dir):
    """Remove a previous run's OUTPUTS from a folder (nothing else in it)."""
    for name in OUTPUTS:
        (pathlib.Path(out_dir) / name).unlink(missing_ok=True)


def replace_file(path, write):
    """Call write(temporary path) beside path, then rename it over path; clean up if not."""
    temporary = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
    try:
        write(temporary)
        if path.name == OUTPUTS[0]:  # the new schedule: the old picture goes first
            clear_outputs(path.parent)
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def summary(result):
    """Return the terminal summary: per step, magnetisation, robustness, flags."""
    scene, plan = result.scene, result.plan
    length = scene.tentacle.length_m
    lines = [f'{scene.name}: {len(plan.steps)} key steps'
             + (f', {len(result.playback_steps)} playback steps' if result.playback_steps
                else '') + (' [INTERRUPTED: best plan so far]' if result.interrupted else ''),
             '  step  inserted   field (mT)                 shape RMS        tip error  stability'
             + ('  clearance' if scene.obstacles or scene.walls else '')
             + ('   backbone' if scene.backbone_steps_m else '')]
    for k, step in enumerate(plan.steps):
        rms, tip = scene.shape_error(step)
        b = ' '.join(f'{v * 1e3:7.2f}' for v in step.field_t)
        gap = (f'  {step_clearance(scene, step)[0] * 1e3:6.2f} mm' if scene.obstacles
               or scene.walls else '')
        gap += f'  {step.backbone_m * 1e3:6.1f} mm' if scene.backbone_steps_m else ''
        lines.append(f'  {k + 1:4d}  {step.inserted_m * 1e3:6.1f} mm  {b}   '
                     f'{rms * 1e3:6.3f} mm {100 * rms / length:5.2f}%   {tip * 1e3:6.3f} mm  '
                     f'{step.stability:9.3g}{gap}')
    angles = magnetisation_angles_deg(plan.directions)
    given = ' (given by the tentacle file)' if scene.magnetisation.given else ''
    lines.append(f'  magnetisation{given} (azimuth, elevation in the link frame, deg): '
                 + ', '.join(f'{i + 1}: ({angles[i, 0]:.1f}, {angles[i, 1]:.1f})'
                             for i, d in enumerate(plan.directions) if np.any(d)))
    walls = bool(scene.obstacles or scene.walls)
    for rows, whose in ((result.robustness, 'robustness: nominal'),
                        (result.robust_robustness, 'robust plan: nominal')):
        if not rows:   # none when Ctrl-C left the report out, or without --robust
            continue
        worst = max(rows, key=lambda row: row[2])
        deepest = max(rows, key=lambda row: row[3])
        lines.append(f'  {whose} {rows[0][2] * 1e3:.3f} mm, worst {worst[2] * 1e3:.3f} mm '
                     f'({worst[0]})' + (f'; into a wall up to {deepest[3] * 1e3:.3f} mm '
                                        f'({deepest[0]})' if deepest[3] > 0 else
                                        '; off the walls in every model' if walls else ''))
    for rows, whose in ((result.robustness, 'the nominal plan'),
                        (result.robust_robustness, 'the robust plan')):
        lines += [f'  on {name}: {whose} {total * 1e3:.3f} mm'
                  + (f', {depth * 1e3:.3f} mm into a wall' if depth > 0 else '')
                  for name, _, total, depth in rows if name.startswith(ON_THE_RIG)]
    planned = shape_rms(scene, plan.steps)
    for what, rms in result.verification:
        lines.append(f'  re-checked in {what}: shape RMS {rms * 1e3:.3f} mm '
                     f'({(rms - planned) * 1e3:+.3f} mm on the planning model)')
    lines += [f'  FLAG: {flag}' for flag in result.flags] or ['  no flags']
    return '\n'.join(lines)
