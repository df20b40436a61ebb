"""
DIR/plot.png of a study's table: the tip (a plan's error) against one varied name, or maps.

A twist-stability study (twist_stability over field_angle_deg and field_strength_t, and
perhaps one more name, e.g. a reinforcement's) draws its stability map instead. matplotlib is
imported here only, when a plot is drawn: a cluster's workers never need it.
"""

import numpy as np
from tentacle_studies.study import FIELD_POLAR

MAX_PLOTTED = 200_000   # points drawn at most (every k-th beyond): a map, not a census


def least_over_fields(table, name):
    """
    Return (values of name, least twist stability over every field at each), sorted by value.

    nan where a value has no converged planar point; N m / rad^2.
    """
    values = np.asarray(table.column(name).to_numpy(), float)
    stability = np.asarray(table.column('twist_stability').to_numpy(), float)
    keys = np.unique(values)
    least = np.array([np.nanmin(stability[values == v]) if np.any(
        np.isfinite(stability[values == v])) else np.nan for v in keys])
    return keys, least


def _pyplot():
    import matplotlib
    matplotlib.use('Agg')   # files only: no display on a lab's compute node
    import matplotlib.pyplot as plt
    return plt


def _stability_map(table, names, path, title):
    """Draw twist stability over the field (polar) and its least against the other name."""
    plt = _pyplot()
    others = [n for n in names if n not in FIELD_POLAR]
    column = {n: np.asarray(table.column(n).to_numpy(), float)
              for n in [*names, 'twist_stability']}
    fig = plt.figure(figsize=(11 if others else 6, 4.8))
    at = np.ones(table.num_rows, bool)
    if others:
        ax = fig.add_subplot(1, 2, 1)
        keys, least = least_over_fields(table, others[0])
        ax.plot(keys, least, 'o-')
        ax.axhline(0.0, color='k', lw=0.8)
        if keys.min() > 0 and keys.max() > 100 * keys.min():
            ax.set_xscale('log')
        ax.set_xlabel(others[0])
        ax.set_ylabel('least twist stability over the field (N m/rad$^2$)')
        ax.set_title('below zero: the planar shape twists somewhere', fontsize=9)
        at = column[others[0]] == keys[0]
    polar = fig.add_subplot(1, 2, 2 if others else 1, projection='polar')
    theta = np.radians(column['field_angle_deg'][at])
    radius = 1e3 * column['field_strength_t'][at]
    value = column['twist_stability'][at]
    dots = polar.scatter(theta, radius, c=value, s=14, cmap='viridis')
    polar.set_rlabel_position(292.5)   # the strengths' labels between the rays
    unstable = value <= 0
    if unstable.any():
        polar.plot(theta[unstable], radius[unstable], 'rx', ms=4, label='twists')
        polar.legend(loc='lower left', bbox_to_anchor=(-0.15, -0.12), fontsize=8)
    fig.colorbar(dots, ax=polar, label='twist stability (N m/rad$^2$)', pad=0.1)
    polar.set_title('field angle (deg) and strength (mT)'
                    + (f', {others[0]} = {column[others[0]][at][0]:g}' if others else ''),
                    fontsize=9)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_table(table, names, path, title):
    """
    Draw the tip (mm) against one varied name, or its x and y over two; return path or None.

    A plan study's: its shape error planned and re-checked. Unstable or unconverged points
    (flagged plans) are marked. With more than two varied names there is no
    plot (None): the table is the result. A twist-stability study over the field (and at
    most one more name) draws its stability map.
    """
    if table.num_rows == 0:
        return None
    if 'twist_stability' in table.column_names and set(FIELD_POLAR) <= set(names) \
            and len(names) <= 3:
        return _stability_map(table, names, path, title)
    if len(names) not in (1, 2):
        return None
    plt = _pyplot()
    step = max(1, table.num_rows // MAX_PLOTTED)
    plans = 'shape_rms_m' in table.column_names
    drawn = ['shape_rms_m', 'recheck_rms_m'] if plans else ['tip_x_m', 'tip_y_m', 'tip_z_m']
    columns = {name: np.asarray(table.column(name).to_numpy())[::step]
               for name in [*names, *drawn]}
    if plans:
        flags = table.column('flags').to_pylist()[::step]
        bad, mark, label = np.array([bool(f) for f in flags]), drawn[1], 'flagged'
    else:
        bad = ~np.asarray(table.column('stable').to_numpy())[::step].astype(bool)
        mark, label = 'tip_y_m', 'not stable'
    if len(names) == 1:
        fig, ax = plt.subplots(figsize=(7, 4))
        x = columns[names[0]]
        order = np.argsort(x, kind='stable')
        for name in drawn:
            ax.plot(x[order], 1e3 * columns[name][order], '.-', ms=3,
                    label=name[:-2].replace('_', ' '))
        if bad.any():
            ax.plot(x[bad], 1e3 * columns[mark][bad], 'kx', label=label)
        ax.set_xlabel(names[0])
        ax.set_ylabel('shape error, RMS (mm)' if plans else 'tip (mm)')
        ax.legend()
    else:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
        a, b = columns[names[0]], columns[names[1]]
        for ax, name in zip(axes, drawn[:2]):
            dots = ax.scatter(a, b, c=1e3 * columns[name], s=8, cmap='viridis')
            fig.colorbar(dots, ax=ax, label=f'{name[:-2].replace("_", " ")} (mm)')
            if bad.any():
                ax.plot(a[bad], b[bad], 'rx', ms=4, label=label)
                ax.legend(loc='upper right')
            ax.set_xlabel(names[0])
            ax.set_ylabel(names[1])
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
