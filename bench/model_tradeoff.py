#!/usr/bin/env python3
"""
Benchmark: the statics model's speed against its accuracy, and against a Cosserat-rod peer.

For standard scenes (the validation cantilever at 90, 135 and 180 degrees to a 5 mT field;
the chapter 5 braided tentacle fully inserted in an out-of-plane field; the chapter 6 strip
of 24 segments, in a fixed field and coiling as its backbone is withdrawn) it solves at
every fidelity setting (linearised and nonlinear, planar and 3-DoF, with and without
magnet-to-magnet interaction; 1 to 64 sub-links per segment) and prints the time per
forward solve (median, cold start and warm start from a nearby state; the coiling strip
step by step along its path) beside the tip error against a converged reference of the
same scene, checks the issue's speed targets, then writes bench/out/model_tradeoff.png
(error against time: the Pareto front). The peer, PyElastica with magneto-pyelastica
(bench/peer_elastica.py), relaxes the 90 degree cantilever with damping; its wall time to
settle within 1% of L is set beside ours at the same accuracy, timed back to back in the
same run.

Run: make bench-model (creates the bench-only .venv-bench with the peer).
"""

import argparse
from dataclasses import replace
import json
import os
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [*(str(p) for p in sorted((ROOT / 'src').iterdir())
                  if (p / 'package.xml').exists()), str(ROOT / 'bench')]

import numpy as np  # noqa: E402
from tentacle_model.chain import discretise  # noqa: E402
from tentacle_model.model import TentacleModel  # noqa: E402
from tentacle_model.statics import solve  # noqa: E402
from tentacle_model.tentacle_spec import load_tentacle  # noqa: E402
from tentacle_studies import equilibria  # noqa: E402
from tentacle_studies.study import load_study  # noqa: E402
from tentacle_studies.surrogate import Surrogate  # noqa: E402

TENTACLES = ROOT / 'config' / 'tentacles'
SUBLINKS = (1, 2, 4, 8, 10, 16, 32, 64)  # 10: the braided tentacle at 50 links


def field(magnitude_t, degrees):
    """Return the in-plane field vector (3,), tesla, at an angle to +x in degrees."""
    phi = np.radians(degrees)
    return magnitude_t * np.array([np.cos(phi), np.sin(phi), 0.0])


SCENES = {  # name: (tentacle file, field in tesla, models to try, reference setting)
    'cantilever 90': ('cantilever', field(5e-3, 90), ('linear', 'planar', '3dof'),
                      ('planar', 1024)),
    'cantilever 135': ('cantilever', field(5e-3, 135), ('linear', 'planar', '3dof'),
                       ('planar', 1024)),
    'cantilever 180': ('cantilever', field(5e-3, 180), ('planar', '3dof'), ('planar', 1024)),
    'braided 5-link': ('braided_chapter5', np.array([0.0, 0.012, 0.006]),
                       ('linear3', '3dof', '3dof+dip'), ('3dof', 24)),
    'chapter 6 strip': ('vsr_chapter6', np.array([0.0, 0.015, 0.0]), ('planar', '3dof'),
                        ('planar', 256)),
}
MODELS = {'linear': {'dof': 1, 'linear': True}, 'planar': {'dof': 1}, '3dof': {'dof': 3},
          'linear3': {'dof': 3, 'linear': True}, '3dof+dip': {'dof': 3, 'dipoles': True}}
# Reference settings are the scene's with the same terms: a dipole row is compared with a
# dipole reference (the interaction is a different scene, not an error of the model).
REFERENCE_TERMS = {'3dof+dip': {'dipoles': True}}


def timed_solve(chain, b, model, repeats):
    """Return (equilibrium, median cold seconds, median warm seconds)."""
    options = MODELS[model]
    cold = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        eq = solve(chain, b, **options)
        cold.append(time.perf_counter() - t0)
    warm = []
    for _ in range(repeats if eq.converged else 0):
        t0 = time.perf_counter()
        solve(chain, 1.01 * b, initial=eq.angles_rad, **options)
        warm.append(time.perf_counter() - t0)
    return eq, float(np.median(cold)), float(np.median(warm)) if warm else float('nan')


def run_scenes(quick):
    """Return a list of result rows over all scenes and settings."""
    rows = []
    # Compile (or load from numba's cache) once per process, before anything is timed.
    solve(discretise(load_tentacle(TENTACLES / 'cantilever.yaml')), [0.0, 1e-3, 0.0])
    for name, (tentacle, b, models, (ref_model, ref_sublinks)) in SCENES.items():
        spec = load_tentacle(TENTACLES / f'{tentacle}.yaml')
        length = spec.length_m
        t0 = time.perf_counter()
        reference = solve(discretise(spec, sublinks=ref_sublinks), b, **MODELS[ref_model])
        reference_s = time.perf_counter() - t0
        assert reference.converged, (name, reference.reason)
        print(f'{name}: reference {ref_model} x{ref_sublinks} sub-links in '
              f'{reference_s * 1e3:.1f} ms', flush=True)
        references = {}
        for model in models:
            terms = REFERENCE_TERMS.get(model)
            if terms and str(terms) not in references:
                references[str(terms)] = solve(discretise(spec, sublinks=ref_sublinks), b,
                                               **MODELS[ref_model], **terms)
            ref_tip = references[str(terms)].tip_m if terms else reference.tip_m
            for sublinks in SUBLINKS:
                chain = discretise(spec, sublinks=sublinks)
                if model != 'planar' and MODELS[model]['dof'] == 3 and chain.size > 160:
                    continue  # dense Newton: past 160 links the reference is cheaper
                eq, cold_s, warm_s = timed_solve(chain, b, model, 3 if quick else 9)
                error = float(np.linalg.norm(eq.tip_m - ref_tip) / length) \
                    if eq.converged else float('nan')
                rows.append({'scene': name, 'model': model, 'sublinks': sublinks,
                             'links': chain.size, 'converged': eq.converged,
                             'cold_ms': cold_s * 1e3, 'warm_ms': warm_s * 1e3,
                             'tip_error_of_L': error, 'reference_ms': reference_s * 1e3})
    return rows


def coiling_path(spec, sublinks, options, steps=24, field_t=0.02, radius_m=0.0075):
    """
    Yield (chain, field) of each step of the chapter 6 coiling (test_backbone.py).

    The backbone is withdrawn while the field turns with it: with l of the strip released,
    the field at l / r holds the released part in the coil its magnetisation describes.
    """
    length = spec.length_m
    for released in np.linspace(0.0, length, steps + 1)[1:]:
        angle = released / radius_m
        yield (discretise(spec, sublinks=sublinks, backbone_m=length - released),
               field_t * np.array([np.cos(angle), np.sin(angle), 0.0]))


def run_coiling(quick):
    """
    Return result rows for the coiling strip: each step warm-started from the last.

    The warm column is the median step along the path (how the planner and the simulator
    use the model); the cold column solves the last step from straight, which lands on
    another branch (history decides the shape): its error is given apart.
    """
    spec = load_tentacle(TENTACLES / 'vsr_chapter6.yaml')

    def follow(sublinks, model):
        state, times, converged = None, [], True
        for chain, b in coiling_path(spec, sublinks, MODELS[model]):
            t0 = time.perf_counter()
            eq = solve(chain, b, initial=state, **MODELS[model])
            times.append(time.perf_counter() - t0)
            state, converged = eq.angles_rad, converged and eq.converged
        return eq, chain, b, float(np.median(times)), converged

    t0 = time.perf_counter()
    reference = follow(32, 'planar')[0]
    reference_ms = (time.perf_counter() - t0) * 1e3  # the whole path
    print(f'chapter 6 coiling: reference planar x32 along the 24-step path in '
          f'{reference_ms:.1f} ms, tip heading {np.degrees(reference.angles_rad[-1]):.0f} deg',
          flush=True)
    rows = []
    for model in ('planar', '3dof'):
        for sublinks in (1, 2, 4, 8, 16):
            if model == '3dof' and sublinks > 4:
                continue
            eq, chain, b, step_s, converged = follow(sublinks, model)
            cold = timed_solve(chain, b, model, 3 if quick else 9)
            rows.append({'scene': 'chapter 6 coiling', 'model': model, 'sublinks': sublinks,
                         'links': chain.size, 'converged': converged,
                         'cold_ms': cold[1] * 1e3, 'warm_ms': step_s * 1e3,
                         'tip_error_of_L': float(np.linalg.norm(eq.tip_m - reference.tip_m)
                                                 / spec.length_m),
                         'cold_tip_error_of_L': float(np.linalg.norm(
                             cold[0].tip_m - reference.tip_m) / spec.length_m),
                         'reference_ms': reference_ms})
    return rows


CHAPTER2_SHAPES = 200
CHAPTER2_SUBLINKS = (1, 2, 4, 8, 16, 32)
CHAPTER2_REFERENCE_SUBLINKS = 128


def run_chapter2(quick):
    """
    Return rows for chapter 2's tentacle at new magnetisations: the model and its surrogate.

    The surrogate (tentacle_studies.surrogate: two hidden layers of 64) is trained on the
    13,824-point babble (config/studies/ch2_babble.yaml, planar x8) to give the tip; the
    error is the mean over 200 magnetisations drawn at random (off the babble's grid), each
    solved from straight, of the tip's distance from planar x128's over L. cold ms: one
    shape (statics through TentacleModel.solve, or one surrogate call); warm ms: a shape in
    batch (tentacle_model.batch, or one surrogate call for all 200).
    """
    study = load_study(ROOT / 'config' / 'studies' / 'ch2_babble.yaml')
    spec, names = study.tentacle, study.names
    rng = np.random.default_rng(0)
    angles = rng.uniform(0.0, 2 * np.pi, (CHAPTER2_SHAPES, len(names)))
    points = {name: np.degrees(angles[:, k]) for k, name in enumerate(names)}

    def tips(sublinks):
        t0 = time.perf_counter()
        columns = equilibria.solve_at(replace(study, sublinks=sublinks), points, warm=False)
        per_shape = (time.perf_counter() - t0) / CHAPTER2_SHAPES
        return np.column_stack([columns['tip_x_m'], columns['tip_y_m']]), per_shape, \
            bool(columns['converged'].all())

    reference = tips(CHAPTER2_REFERENCE_SUBLINKS)[0]
    print(f'chapter 2: {CHAPTER2_SHAPES} magnetisations against planar '
          f'x{CHAPTER2_REFERENCE_SUBLINKS}; cold ms: one shape, warm ms: a shape in batch',
          flush=True)

    def error(found):
        return float(np.mean(np.linalg.norm(found - reference, axis=1)) / spec.length_m)

    rows = []
    repeats = 1 if quick else 3
    for sublinks in CHAPTER2_SUBLINKS:
        found, batch_s, converged = min((tips(sublinks) for _ in range(repeats)),
                                        key=lambda t: t[1])
        model = TentacleModel(spec, dof=1, sublinks=sublinks, gravity_m_s2=study.gravity_m_s2)
        moments = [_moments(model, spec, a) for a in angles[:40]]
        single = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            for m in moments:
                model.solve(spec.length_m, study.field_t, None, m)
            single.append((time.perf_counter() - t0) / len(moments))
        rows.append({'scene': 'chapter 2 (200 shapes)', 'model': 'planar',
                     'sublinks': sublinks, 'links': model.chain(spec.length_m).size,
                     'converged': converged, 'cold_ms': min(single) * 1e3,
                     'warm_ms': batch_s * 1e3, 'tip_error_of_L': error(found),
                     'reference_ms': float('nan')})
    babble = equilibria.solve_points(study, 0, study.size)
    trained = np.radians(np.column_stack([babble[n] for n in names]))
    t0 = time.perf_counter()
    surrogate = Surrogate().fit(trained, np.column_stack([babble['tip_x_m'],
                                                          babble['tip_y_m']]))
    fit_s = time.perf_counter() - t0
    one = min(_timed(lambda: [surrogate(a) for a in angles]) for _ in range(repeats * 3))
    every = min(_timed(lambda: surrogate(angles)) for _ in range(repeats * 3))
    rows.append({'scene': 'chapter 2 (200 shapes)', 'model': 'surrogate',
                 'sublinks': study.sublinks, 'links': 6 * study.sublinks, 'converged': True,
                 'cold_ms': one / CHAPTER2_SHAPES * 1e3,
                 'warm_ms': every / CHAPTER2_SHAPES * 1e3,
                 'tip_error_of_L': error(surrogate(angles)), 'reference_ms': float('nan'),
                 'note': f'trained on the {study.size}-point babble at x{study.sublinks} in '
                         f'{fit_s:.0f} s'})
    return rows


def _moments(model, spec, angles_rad):
    """Return (n, 3) link moments of chapter 2's tentacle with its magnets at angles_rad."""
    chain = model.chain(spec.length_m)
    directions = np.array([[1.0, 0.0, 0.0]] * len(spec.segments))
    directions[1::2] = np.column_stack([np.cos(angles_rad), np.sin(angles_rad),
                                        np.zeros(len(angles_rad))])
    return np.linalg.norm(chain.moments_a_m2, axis=1)[:, None] * \
        directions[chain.segment_index]


def _timed(call):
    t0 = time.perf_counter()
    call()
    return time.perf_counter() - t0


def run_peer(rows, max_wall_s):
    """Time PyElastica to 1% of L on the 90 degree cantilever; compare with ours there."""
    try:
        from peer_elastica import relax_cantilever
    except ImportError as exc:
        print(f'peer: not available ({exc}); run `make bench-model`')
        return None
    spec = load_tentacle(TENTACLES / 'cantilever.yaml')
    segment = spec.segments[0]
    length = spec.length_m
    reference = solve(discretise(spec, sublinks=1024), SCENES['cantilever 90'][1])
    magnetisation = float(np.linalg.norm(segment.magnetisation_a_per_m))
    kwargs = {'length_m': length, 'diameter_m': 2 * np.sqrt(segment.area_m2 / np.pi),
              'youngs_pa': segment.modulus_pa[0], 'density_kg_m3': segment.density_kg_m3,
              'magnetisation_a_per_m': magnetisation, 'field_t': SCENES['cantilever 90'][1],
              'reference_tip_m': reference.tip_m[:2]}
    relax_cantilever(10, tolerance_m=0.0, max_wall_s=1.0, **kwargs)  # numba compiles here
    relax_cantilever(10, tolerance_m=0.0, max_wall_s=1.0, compiled_torque=True, **kwargs)
    # Ours at equal accuracy: the fastest nonlinear setting within 1% of L.
    ours = min((r for r in rows if r['scene'] == 'cantilever 90' and r['model'] != 'linear'
                and r['tip_error_of_L'] <= 0.01), key=lambda r: r['cold_ms'])
    chain = discretise(spec, sublinks=ours['sublinks'])

    def ours_ms():
        return timed_solve(chain, kwargs['field_t'], ours['model'], 31)[1] * 1e3

    variants = {}
    for compiled in (False, True):  # magneto-pyelastica's torque as shipped; compiled
        name = 'compiled torque' if compiled else 'as shipped'
        survey = {}
        # 50 rests 1.43% of L off and 80 0.89% (peer_elastica.py): 80 is its coarsest within 1%.
        for elements in (50, 80, 100, 200):
            survey[elements] = relax_cantilever(elements, tolerance_m=0.01 * length,
                                                max_wall_s=max_wall_s,
                                                compiled_torque=compiled, **kwargs)
            print(f'peer ({name}): {elements} elements -> {survey[elements]}', flush=True)
        fastest = min((k for k, r in survey.items() if r['wall_s_to_tolerance'] is not None),
                      key=lambda k: survey[k]['wall_s_to_tolerance'], default=None)
        # The ratio: ours and the peer's fastest timed back to back, three times, so that
        # this machine's drifting speed (2x between minutes) falls on both alike.
        pairs = []
        for _ in range(3 if fastest else 0):
            mine = ours_ms()
            peer = relax_cantilever(fastest, tolerance_m=0.01 * length, max_wall_s=max_wall_s,
                                    compiled_torque=compiled, **kwargs)['wall_s_to_tolerance']
            pairs.append({'ours_ms': mine, 'peer_s': peer, 'ratio': peer / (mine / 1e3)})
        variants[name] = {'survey': {str(k): v for k, v in survey.items()},
                          'elements': fastest, 'pairs': pairs}
    return {'ours': ours, 'variants': variants}


def print_table(rows):
    """Print one row per scene, model and sub-link count."""
    print(f'\n{"scene":17} {"model":8} {"sub":>4} {"links":>5} {"cold ms":>9} {"warm ms":>9} '
          f'{"tip error / L":>14}')
    for r in rows:
        note = '' if r['converged'] else '  (not converged)'
        if 'note' in r:
            note += '  ' + r['note']
        if 'cold_tip_error_of_L' in r:
            note += (f'  warm: median step of the path; from straight the tip lands '
                     f'{r["cold_tip_error_of_L"]:.2f} L away (another branch)')
        print(f'{r["scene"]:17} {r["model"]:8} {r["sublinks"]:4d} {r["links"]:5d} '
              f'{r["cold_ms"]:9.4f} {r["warm_ms"]:9.4f} {r["tip_error_of_L"]:14.2e}' + note)


PATH_SCENES = {'chapter 6 coiling'}  # solved step by step along a history
STYLES = {  # model: (marker, colour, legend label)
    'linear': ('s', 'C0', 'planar, linearised'), 'planar': ('o', 'C1', 'planar'),
    '3dof': ('^', 'C2', '3-DoF'), 'linear3': ('v', 'C3', '3-DoF, linearised'),
    '3dof+dip': ('D', 'C4', '3-DoF + dipoles (against its own reference)'),
    'surrogate': ('*', 'C5', 'surrogate (a network trained on the model)')}


def plot(rows, path):
    """Write error against time per scene, with the Pareto front, to a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib.ticker import NullFormatter
    import matplotlib.pyplot as plt
    scenes = list(dict.fromkeys(r['scene'] for r in rows))
    fig, grid = plt.subplots(2, 4, figsize=(17, 7.5), sharey=True)
    axes = grid.ravel()
    for ax, scene in zip(axes, scenes):
        # A path scene is timed per step, warm-started: that is how it is solved.
        key = 'warm_ms' if scene in PATH_SCENES else 'cold_ms'
        for model, (marker, colour, label) in STYLES.items():
            pts = [(r[key], max(r['tip_error_of_L'], 1e-9)) for r in rows
                   if r['scene'] == scene and r['model'] == model and r['converged']]
            if pts:
                ax.loglog(*zip(*pts), marker=marker, color=colour, label=label)
        # The front over the settings of one scene: the dipole rows are another scene.
        front = sorted((r[key], max(r['tip_error_of_L'], 1e-9)) for r in rows
                       if r['scene'] == scene and r['converged'] and r['model'] != '3dof+dip')
        best, pareto = np.inf, []
        for t, e in front:
            if e < best:
                best = e
                pareto.append((t, e))
        ax.step(*zip(*pareto), where='post', color='k', lw=0.8, label='Pareto front')
        ax.axhline(0.01, color='grey', ls=':', lw=0.8, label='1% of L')
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(scene + (' (warm, per step of the path)' if scene in PATH_SCENES
                              else ''), fontsize=10)
        ax.set_xlabel('time per solve, ' + ('warm' if scene in PATH_SCENES else 'cold start')
                      + ' (ms)')
        ax.grid(True, which='major', lw=0.3)
    for ax in grid[:, 0]:
        ax.set_ylabel('tip error / L')
    handles = {}
    for ax in axes[:len(scenes)]:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    for ax in axes[len(scenes):]:
        ax.axis('off')
    axes[-1].legend(handles.values(), handles.keys(), loc='center', fontsize=9,
                    title='each point: one setting (sub-links per segment)')
    fig.suptitle('Statics model: accuracy against time per forward solve (this machine)')
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    print(f'plot: {path}')


def print_targets(rows):
    """Print the issue's speed targets against the measured medians."""
    def cold_ms(links):
        return next(r['cold_ms'] for r in rows if r['scene'] == 'braided 5-link'
                    and r['model'] == '3dof' and r['links'] == links)

    def verdict(value, limit):
        return 'met' if value <= limit else 'NOT met'

    five, fifty = cold_ms(5), cold_ms(50)
    slowest = max(r['reference_ms'] for r in rows)
    print('\ntargets (median per solve, cold start):')
    print(f'  5-link 3-DoF nonlinear (braided): {five:.3f} ms; 1 ms: {verdict(five, 1.0)}')
    print(f'  50 links 3-DoF (braided x10): {fifty:.3f} ms; 10 ms: {verdict(fifty, 10.0)}')
    print(f'  converged references: at most {slowest:.1f} ms; 1 s: {verdict(slowest, 1e3)}')


def main():
    """Run every scene and setting, then the peer; print, save JSON and the plot."""
    parser = argparse.ArgumentParser(description=__doc__.strip().split('\n')[0])
    parser.add_argument('--quick', action='store_true', help='fewer repeats')
    parser.add_argument('--no-peer', action='store_true', help='skip PyElastica')
    parser.add_argument('--peer-seconds', type=float, default=30.0)
    opts = parser.parse_args()
    rows = run_scenes(opts.quick) + run_coiling(opts.quick) + run_chapter2(opts.quick)
    print_table(rows)
    print_targets(rows)
    peer = None if opts.no_peer else run_peer(rows, opts.peer_seconds)
    if peer:
        ours = peer['ours']
        print(f'\nat 1% of L on the 90 degree cantilever: ours {ours["model"]} '
              f'x{ours["sublinks"]} (error {ours["tip_error_of_L"]:.2%}), cold solves')
        for name, v in peer['variants'].items():
            if not v['pairs']:
                print(f'  PyElastica + magneto-pyelastica ({name}): never within 1%')
                continue
            ratios = sorted(p['ratio'] for p in v['pairs'])
            print(f'  against PyElastica + magneto-pyelastica ({name}, {v["elements"]} '
                  'elements): ' + ', '.join(f'{p["peer_s"]:.2f} s / {p["ours_ms"]:.2f} ms'
                                            for p in v['pairs'])
                  + f': median {ratios[len(ratios) // 2]:.0f}x (range {ratios[0]:.0f}-'
                  f'{ratios[-1]:.0f}x)')
    out = ROOT / 'bench' / 'out'
    out.mkdir(parents=True, exist_ok=True)
    (out / 'model_tradeoff.json').write_text(json.dumps({'rows': rows, 'peer': peer},
                                                        indent=2, default=str))
    plot(rows, out / 'model_tradeoff.png')
    print(f'machine: {os.cpu_count()} cores')


if __name__ == '__main__':
    main()
