#!/usr/bin/env python3
"""
Benchmark: thesis chapter 2 reproduced, its babble, learned inverse and shapes, on one core.

The 24^3 magnetisation study (config/studies/ch2_babble.yaml) solved in this process beside
the thesis' 38 hours; the redundancy removal (thesis: 2298 of 13,824 kept); the thesis'
network (six hidden layers of 20) trained on 70% of the kept points, its outputs' error on
15% (thesis: 6.3%) and, on the last 15% and on 100 new shapes (made in the forward model by
angles drawn inside the kept arcs, none on the grid), the angles it gives checked in the
forward model (the thesis' error: summed |achieved - requested| over summed |requested|),
for 5 seeds of its initial weights. Then shapes, method by method (seed 0's network): the
new shapes and the thesis' scenarios A, B and C (Fig. 2.9: [2 6 5], [-1 -2 1] and
[1 0 -5] mm), by the network alone, the network's answer polished in the forward model,
the nearest point of the whole table (a lookup), and the forward model optimised directly
from that point, as the planner optimises (no network): the error of the answers checked
in the forward model, and the time to give one. Writes bench/out/ch2_inverse.png.

Run: .venv/bin/python bench/ch2_inverse.py
"""

import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]

import matplotlib  # noqa: E402
matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from sklearn.model_selection import train_test_split  # noqa: E402
from tentacle_studies import equilibria, inverse  # noqa: E402
from tentacle_studies.study import load_study  # noqa: E402

STUDY = ROOT / 'config' / 'studies' / 'ch2_babble.yaml'
OUT = ROOT / 'bench' / 'out' / 'ch2_inverse.png'
THESIS_HOURS = 38.0
THESIS_KEPT = 2298
THESIS_ERROR = 0.063
SCENARIOS_MM = {'A': (2.0, 6.0, 5.0), 'B': (-1.0, -2.0, 1.0), 'C': (1.0, 0.0, -5.0)}
SEED = 0
SEEDS = 5   # the network's initial weights: its errors spread with them
NEW_SHAPES = 100


def sweep(study):
    """Return (columns, seconds) of the whole study solved in this process."""
    equilibria.solve_at(study, study.points(0, 2))   # compiled kernels loaded: not timed
    t0 = time.perf_counter()
    columns = equilibria.solve_points(study, 0, study.size)
    return columns, time.perf_counter() - t0


def split(angles, deflections):
    """Return the thesis' 70/15/15 split: (train, validation, test), each (angles, defl.)."""
    a_train, a_rest, d_train, d_rest = train_test_split(angles, deflections, test_size=0.3,
                                                        random_state=SEED)
    a_val, a_test, d_val, d_test = train_test_split(a_rest, d_rest, test_size=0.5,
                                                    random_state=SEED)
    return (a_train, d_train), (a_val, d_val), (a_test, d_test)


def answers_by(method, requested):
    """Return (angles (N, k), rad, seconds a shape) of method(requested (k,)) shape by shape."""
    answers, t0 = [], time.perf_counter()
    for want in requested:
        answers.append(method(want))
    return np.array(answers), (time.perf_counter() - t0) / len(requested)


def trained(study, names, train, validation, test, new, seed):
    """Return the thesis' network trained with seed, having printed its errors."""
    t0 = time.perf_counter()
    network = inverse.Inverse(seed=seed).fit(train[1], train[0])
    fit_s = time.perf_counter() - t0
    wanted = np.hstack([np.cos(validation[0]), np.sin(validation[0])])
    outputs_error = np.abs(network.outputs(validation[1]) - wanted).sum() / np.abs(wanted).sum()
    t0 = time.perf_counter()
    answers = network.angles_rad(test[1])
    batch_us = (time.perf_counter() - t0) / len(test[1]) * 1e6
    achieved, _ = inverse.forward(study, names, answers)
    on_new, _ = inverse.forward(study, names, network.angles_rad(new))
    miss = np.degrees(np.abs((answers - test[0] + np.pi) % (2 * np.pi) - np.pi))
    print(f'  seed {seed}: fitted in {fit_s:.1f} s; outputs off by {100 * outputs_error:.1f}% '
          f'on validation; on test angles off by {miss.mean():.1f} deg mean, forward-checked '
          f'error {100 * inverse.deflection_error(achieved, test[1]):.1f}%; new shapes '
          f'{100 * inverse.deflection_error(on_new, new):.1f}%; {batch_us:.1f} us an answer '
          'in batch')
    return network


def new_shapes(study, grid, arcs, count=NEW_SHAPES):
    """Return (count, k) deflections, m, of angles drawn uniformly inside the kept arcs."""
    rng = np.random.default_rng(SEED)
    low = np.array([grid.angles_deg[k][arc[0]] for k, arc in enumerate(arcs)])
    span = np.array([np.diff(grid.angles_deg[k][:2])[0] * (len(arc) - 1)
                     for k, arc in enumerate(arcs)])
    return inverse.forward(study, grid.names, np.radians(low + rng.random((count, 3)) * span))[0]


def main():
    """Print the chapter 2 figures and write the plot."""
    study = load_study(STUDY)
    columns, seconds = sweep(study)
    print(f'chapter 2 babble: {study.size} equilibria in {seconds:.2f} s on one core '
          f'(thesis: {THESIS_HOURS:g} h of FEM on 16 cores, {THESIS_HOURS * 3600 / seconds:,.0f}'
          ' times as long); all stable:', bool(np.all(columns['stable'])))
    grid = inverse.babble(study, columns)
    mask, arcs = inverse.redundancy_mask(grid)
    kept = ', '.join(f'{name} {grid.angles_deg[k][arc[0]]:g}..{grid.angles_deg[k][arc[-1]]:g}'
                     f' deg ({len(arc)})' for k, (name, arc) in enumerate(zip(grid.names, arcs)))
    print(f'kept after redundancy removal: {mask.sum()} of {mask.size} (thesis {THESIS_KEPT}):'
          f' {kept}')
    angles, deflections = grid.points(mask)
    train, validation, test = split(angles, deflections)
    new = new_shapes(study, grid, arcs)
    print(f'thesis network {"x".join(map(str, inverse.THESIS_LAYERS))} (tanh, L-BFGS), '
          f'{len(train[0])}/{len(validation[0])}/{len(test[0])} points (thesis error '
          f'{100 * THESIS_ERROR:.1f}%), seed by seed:')
    networks = [trained(study, grid.names, train, validation, test, new, seed)
                for seed in range(SEEDS)]
    network = networks[0]

    names = grid.names

    def nearest(want):
        return grid.nearest(want)[0]

    def network_alone(want):
        return network.angles_rad(want)[0]

    def network_polished(want):
        return inverse.direct(study, names, want, network.angles_rad(want)[0]).angles_rad

    def direct_from_table(want):
        return inverse.direct(study, names, want, nearest(want)).angles_rad

    methods = {'table lookup': nearest, 'network': network_alone,
               'network + polish': network_polished, 'direct (table start)': direct_from_table}
    scenarios = np.array(list(SCENARIOS_MM.values())) * 1e-3
    print(f'{len(new)} new shapes (made by angles drawn in the kept arcs, off the grid) and '
          'scenarios A, B and C of the thesis, answers checked in the forward model:')
    print(f'{"method":22s} {"new shapes":>11s} {"ms a shape":>11s}   '
          + '   '.join(f'{name:>7s}' for name in SCENARIOS_MM))
    found = {}
    for label, method in methods.items():
        answers, per_shape = answers_by(method, new)
        achieved = inverse.forward(study, names, answers)[0]
        found[label] = inverse.forward(study, names, answers_by(method, scenarios)[0])[0]
        errors = [inverse.deflection_error(a, w) for a, w in zip(found[label], scenarios)]
        print(f'{label:22s} {100 * inverse.deflection_error(achieved, new):10.2f}% '
              f'{per_shape * 1e3:11.2f}   ' + '   '.join(f'{100 * e:6.1f}%' for e in errors))
    plot(study, scenarios, found)
    print(f'wrote {OUT.relative_to(ROOT)}')


def plot(study, scenarios, found):
    """Draw each scenario's requested and achieved deflections along the body."""
    along = np.array(study.points_of_interest_m) * 1e3
    fig, axes = plt.subplots(1, len(scenarios), figsize=(4 * len(scenarios), 4), sharey=True)
    for ax, (name, want), k in zip(axes, zip(SCENARIOS_MM, scenarios), range(len(scenarios))):
        ax.plot(want * 1e3, along, 'ko-', lw=2, label='requested')
        for label, achieved in found.items():
            ax.plot(achieved[k] * 1e3, along, '.--', label=label)
        ax.set_title(f'scenario {name}')
        ax.set_xlabel('deflection x, mm')
        ax.invert_yaxis()
        ax.grid(alpha=0.3)
    axes[0].set_ylabel('along the body, mm (hung from 0)')
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    OUT.parent.mkdir(exist_ok=True)
    fig.savefig(OUT, dpi=120)


if __name__ == '__main__':
    main()
