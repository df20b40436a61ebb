"""
The plan's picture, DIR/plan.png.

The body at every key step against the path and obstacles, the field at the tip, the
magnetisation, and the field schedule. matplotlib is imported here only, and only when a
picture is drawn.
"""

import pathlib

import numpy as np
from tentacle_planner.schedule_writer import replace_file, thinned


def write_plot(out_dir, result):
    """Draw DIR/plan.png (under a temporary name, renamed when done); return its path."""
    path = pathlib.Path(out_dir) / 'plan.png'
    replace_file(path, lambda temporary: plot_plan(result, temporary))
    return path


def plot_plan(result, png_path):
    """Draw the path, obstacles, the body at every key step, magnetisation and fields."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    scene, plan = result.scene, result.plan
    rotation, origin = scene.tentacle.base_rotation, scene.tentacle.base_position_m

    def plane(points):  # the base plane's coordinates, mm
        return (np.asarray(points) - origin) @ rotation[:, :2] * 1e3

    backbone = bool(scene.backbone_steps_m)

    def label(step):  # what tells the steps apart: insertion, or the backbone's free length
        free = step.inserted_m - step.backbone_m
        return f'{free * 1e3:.1f} mm free' if backbone else f'{step.inserted_m * 1e3:.0f} mm'

    fig, (shape_ax, field_ax) = plt.subplots(1, 2, figsize=(12, 5.5))
    path = plane(thinned(scene.path.points_m)[0])
    shape_ax.plot(path[:, 0], path[:, 1], 'k--', lw=1, label='path')
    for sphere in scene.obstacles:
        centre = plane(sphere.centre_m[None])[0]
        shape_ax.add_patch(plt.Circle(centre, sphere.radius_m * 1e3, color='0.8'))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(plan.steps)))
    span = max(np.ptp(path[:, 0]), np.ptp(path[:, 1]), 1.0)
    for step, colour in zip(plan.steps, colours):
        body = plane(step.points_m)
        rms, _ = scene.shape_error(step)
        shape_ax.plot(body[:, 0], body[:, 1], 'o-', color=colour, ms=3,
                      label=f'{label(step)}: RMS {rms * 1e3:.2f} mm')
        b = step.field_t @ rotation[:, :2]
        scale = 0.15 * span / max(np.max(np.abs(plan.fields_t)), 1e-12)
        shape_ax.annotate('', body[-1] + b * scale, body[-1],
                          arrowprops={'arrowstyle': '->', 'color': colour})
    last = plan.steps[-1].points_m
    chain = scene.tentacle_model(dipoles=False).chain(plan.steps[-1].inserted_m)
    for segment in np.unique(chain.segment_index):  # at each segment's first link
        direction = plan.directions[segment]
        if not np.any(direction):
            continue
        link = int(np.argmax(chain.segment_index == segment))
        a, b = plane(last[link:link + 2])
        axis = (b - a) / max(np.linalg.norm(b - a), 1e-12)
        arrow = direction[0] * axis + direction[1] * np.array([-axis[1], axis[0]])
        mid = (a + b) / 2
        shape_ax.annotate('', mid + arrow * 0.06 * span, mid,
                          arrowprops={'arrowstyle': '-|>', 'color': 'crimson'})
    shape_ax.set_aspect('equal')
    shape_ax.set_xlabel('along the insertion direction (mm)')
    shape_ax.set_ylabel('base-plane normal (mm)')
    shape_ax.set_title(f'{scene.name}: body at every key step, field (arrows at the tip), '
                       'magnetisation (red, last step)', fontsize=9)
    shape_ax.legend(fontsize=7, loc='best', ncol=1 + len(plan.steps) // 8)
    played = result.playback_steps or plan.steps
    lengths = [(s.inserted_m - s.backbone_m if backbone else s.inserted_m) * 1e3
               for s in played]
    fields = np.array([s.field_t for s in played]) * 1e3
    for axis, name in enumerate('xyz'):
        field_ax.plot(lengths, fields[:, axis], '.-', label=f'B{name}')
    if scene.coil.max_field_t:
        for sign in (1, -1):
            field_ax.axhline(sign * scene.coil.max_field_t * 1e3, color='0.6', ls=':')
    field_ax.set_xlabel('free length past the backbone (mm)' if backbone
                        else 'inserted length (mm)')
    field_ax.set_ylabel('field (mT, coil frame)')
    field_ax.set_title('field schedule' + (' (dense playback)' if result.playback_steps
                                           else ''), fontsize=9)
    field_ax.legend(fontsize=8)
    try:
        fig.tight_layout()
        fig.savefig(png_path, dpi=110, format='png')
    finally:
        plt.close(fig)
