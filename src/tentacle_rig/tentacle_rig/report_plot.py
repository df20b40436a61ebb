"""
The navigation report's pictures: desired against achieved shapes per step, and errors.

``plot_shapes`` draws one panel per step of a mode (the desired path up to the step's inserted
length, the body the truth saw, the phantom's walls and obstacles), ``plot_errors`` the shape
error per step of every mode on one axis. Matplotlib without a display (Agg). Pure: no rclpy.
"""

import math

import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

COLOURS = {'open_loop': 'tab:orange', 'closed_loop': 'tab:green', 'tip_driven': 'tab:red'}


def _draw_phantom(ax, scene):
    for wall in scene.walls:
        points = np.asarray(wall.points_m) * 1e3
        ax.plot(points[:, 0], points[:, 1], color='0.6', lw=1)
    for obstacle in scene.obstacles:
        centre = np.asarray(obstacle.centre_m) * 1e3
        ax.add_patch(plt.Circle(centre[:2], obstacle.radius_m * 1e3, color='0.8'))


def plot_shapes(png_path, mode, steps, path, scene, columns=10):
    """
    Write a grid of panels, one per step: desired (grey) against achieved (colour), mm.

    :param steps: run_report.StepOutcome of the mode
    :param path: the desired path (paths.Path), frame coils
    """
    rows = max(1, math.ceil(len(steps) / columns))
    fig, axes = plt.subplots(rows, columns, figsize=(1.9 * columns, 1.9 * rows + 0.6),
                             squeeze=False)
    whole = path.points_m * 1e3
    pad = 2.0
    low, high = whole[:, :2].min(axis=0) - pad, whole[:, :2].max(axis=0) + pad
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, step in zip(axes.ravel(), steps):
        ax.set_axis_on()
        _draw_phantom(ax, scene)
        desired = path.at(np.linspace(0.0, min(step.insertion_m, path.length_m), 50)) * 1e3
        body = step.points_m * 1e3
        ax.plot(whole[:, 0], whole[:, 1], color='0.85', lw=0.8)
        ax.plot(desired[:, 0], desired[:, 1], color='0.3', lw=2.0)
        ax.plot(body[:, 0], body[:, 1], color=COLOURS.get(mode, 'tab:blue'), lw=1.3,
                marker='.', ms=2)
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_aspect('equal')
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f'{step.insertion_m * 1e3:.0f} mm: {step.shape_rms_m * 1e3:.2f}',
                     fontsize=7, color='tab:red' if step.contact_depth_m > 0 else 'black')
    fig.suptitle(f'{mode}: desired (grey) and achieved body, per step; title: inserted, '
                 'shape RMS (mm; red: wall contact)', fontsize=9)
    fig.tight_layout()
    fig.savefig(png_path, dpi=90)
    plt.close(fig)


def plot_errors(png_path, modes):
    """Write the shape error per step of each mode: {mode: [StepOutcome]}, mm against mm."""
    fig, ax = plt.subplots(figsize=(7, 3.6))
    for mode, steps in modes.items():
        ax.plot([s.insertion_m * 1e3 for s in steps], [s.shape_rms_m * 1e3 for s in steps],
                color=COLOURS.get(mode), label=f'{mode} (mean '
                f'{np.mean([s.shape_rms_m for s in steps]) * 1e3:.2f} mm)')
    ax.set_xlabel('inserted length (mm)')
    ax.set_ylabel('shape RMS on the truth (mm)')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path, dpi=100)
    plt.close(fig)
