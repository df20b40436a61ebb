"""
DIR/plot.png of a study's table: the tip (a plan's error) against one varied name, or maps.

matplotlib is imported here only, when a plot is drawn: a cluster's workers never need it.
"""

import numpy as np

MAX_PLOTTED = 200_000   # points drawn at most (every k-th beyond): a map, not a census


def plot_table(table, names, path, title):
    """
    Draw the tip (mm) against one varied name, or its x and y over two; return path or None.

    A plan study's: its shape error planned and re-checked. Unstable or unconverged points
    (flagged plans) are marked. With more than two varied names there is no
    plot (None): the table is the result.
    """
    if len(names) not in (1, 2) or table.num_rows == 0:
        return None
    import matplotlib
    matplotlib.use('Agg')   # files only: no display on a lab's compute node
    import matplotlib.pyplot as plt
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
