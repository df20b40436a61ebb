#!/usr/bin/env python3
"""
Benchmark: thesis chapter 4's reinforcement design, by the closed-form estimate, on one core.

The estimate (tentacle_model.reinforcement) on the thesis' single segment (20 mm x 6 mm
Ecoflex 00-30: shear modulus 34 kPa, Young's 102 kPa; a double helix on the 4.5 mm core,
d = 200 um, E = 1 GPa), as Figure 4.4 draws it: bending and twist deflection under a fixed
moment as shares of the unreinforced, (A) over the fibre angle, (B) with N = 4, 6, 8 helices,
(C) over the fibre modulus and (D) the diameter at 85 deg; beside the thesis' findings (the
bend:twist ratio rising up to ~85 deg, the unit gradient at 85 deg, N = 2 dominating, the
tipping point near EA = 30 N). The braid of chapter 5 beside Table 5.1 (5x bending, 100x
twist). Then config/studies/ch4_twist_stability.yaml (8 fibre moduli x 36 field angles x 21
strengths) solved in this process beside the thesis' 40 minutes a field sweep, and the least
reinforcement it finds. Writes bench/out/ch4_reinforcement.png.

Run: .venv/bin/python bench/ch4_reinforcement.py
"""

import math
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]

import matplotlib  # noqa: E402
matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from tentacle_model.reinforcement import pseudo_moduli, Reinforcement  # noqa: E402
from tentacle_studies import equilibria  # noqa: E402
from tentacle_studies.study import load_study  # noqa: E402

STUDY = ROOT / 'config' / 'studies' / 'ch4_twist_stability.yaml'
OUT = ROOT / 'bench' / 'out' / 'ch4_reinforcement.png'
I_M4 = math.pi * 0.003 ** 4 / 4
EI0, GJ0 = 102e3 * I_M4, 34e3 * 2 * I_M4
AREA_200UM = math.pi * 100e-6 ** 2


def shares(angle_deg, fibres=2, modulus=1e9, diameter=200e-6):
    """Return (bending, twist) deflection as shares of the unreinforced segment's."""
    bend, twist = Reinforcement('helices', fibres, math.radians(angle_deg), modulus, diameter,
                                2.25e-3).stiffness_n_m2()
    return EI0 / (EI0 + bend), GJ0 / (GJ0 + twist)


def unit_gradient(bend, twist, along):
    """Return the value of along where d bend / d twist is nearest one."""
    gradient = np.gradient(bend) / np.gradient(twist)
    return along[np.argmin(np.abs(gradient - 1.0))]


def main():
    fig, axes = plt.subplots(1, 4, figsize=(16, 4))
    angles = np.linspace(30.0, 89.5, 1200)
    bend, twist = np.array([shares(a) for a in angles]).T
    high = angles > 70
    print(f'(A) fibre angle, N = 2: bend:twist peaks at {angles[np.argmax(bend / twist)]:.1f} '
          f'deg (thesis: falls away above 85); unit gradient at '
          f'{unit_gradient(bend[high], twist[high], angles[high]):.1f} deg (thesis: 85)')
    at85 = shares(85.0)
    print(f'    at 85 deg: twist {at85[1]:.3f}, bending {at85[0]:.3f} of the unreinforced')
    axes[0].plot(twist, bend, '-', label='N = 2, 30-89.5 deg')
    for a in (30, 50, 70, 80, 85, 88):
        axes[0].annotate(f'{a}', shares(a)[::-1], fontsize=7)
    axes[0].set_title('(A) fibre angle')
    print("(B) N helices, 50-85 deg: N = 2 bending at the same twist, minus N's "
          '(thesis: N = 2 dominates, i.e. above zero):')
    pair = np.linspace(54.8, 89.9, 3000)   # N = 2 past its stiffest angle, twist rising
    pair_bend, pair_twist = np.array([shares(a) for a in pair]).T
    axes[1].plot(twist, bend, 'k-', lw=1, label='N = 2')
    for n in (4, 6, 8):
        b, t = np.array([shares(a, n) for a in np.linspace(50, 85, 8)]).T
        axes[1].plot(t, b, 'o-', ms=3, label=f'N = {n}')
        reach = t >= pair_twist.min()
        gap = np.interp(t[reach], pair_twist, pair_bend) - b[reach]
        print(f'    N = {n}: ' + ' '.join(f'{g:+.3f}' for g in gap)
              + f'  ({(~reach).sum()} angles twist less than N = 2 can)')
    axes[1].set_title('(B) helices')
    ea = np.logspace(-1, 3.5, 2000)
    for ax, name, kw in ((axes[2], 'modulus', lambda x: {'modulus': x / AREA_200UM}),
                         (axes[3], 'diameter', lambda x: {'diameter': math.sqrt(
                             4 * x / 1e9 / math.pi), 'modulus': 1e9})):
        b, t = np.array([shares(85.0, **kw(x)) for x in ea]).T
        ax.plot(t, b, '-')
        thesis = shares(85.0, **kw(1e9 * AREA_200UM))
        ax.plot(thesis[1], thesis[0], 'ro', label="EA 31 N: the thesis' unit gradient")
        ax.legend(fontsize=8, loc='lower right')
        ax.set_title(f'({"C" if name == "modulus" else "D"}) fibre {name} at 85 deg')
        print(f'({"C" if name == "modulus" else "D"}) fibre {name}: unit gradient at EA = '
              f'{unit_gradient(b, t, ea):.0f} N (thesis: about 30 N)')
    for ax in axes:
        ax.set_xlabel('twist (share of unreinforced)')
        ax.set_ylabel('bending (share of unreinforced)')
    axes[0].legend(fontsize=8)
    axes[1].legend(fontsize=8)
    i = math.pi * 0.001 ** 4 / 4
    for kind in ('braid', 'helices'):
        r = Reinforcement(kind, 16, math.radians(45.0), 2.5e9, 1e-4, 0.45e-3)
        moduli = np.array(pseudo_moduli((1e5,) * 3, (i, i), 2 * i, r)) / 1e5
        print(f'braid of chapter 5 (16 x 0.1 mm nylon, 45 deg, assumed), {kind:7}: bending '
              f'x{moduli[0]:.1f}, twist x{moduli[2]:.0f} (Table 5.1: x5, x100)')
    study = load_study(STUDY)
    t0 = time.perf_counter()
    rows = equilibria.solve_points(study, 0, study.size)
    seconds = time.perf_counter() - t0
    print(f'{STUDY.name}: {study.size} points in {seconds:.2f} s ({study.size / seconds:.0f} a '
          f'second; thesis: 40 minutes a sweep of 41 fields), {rows["converged"].sum()} '
          'converged')
    for modulus in np.unique(rows['fibre_modulus_pa']):
        at = rows['fibre_modulus_pa'] == modulus
        least = np.nanmin(rows['twist_stability'][at])
        ea = modulus * math.pi * 2e-4 ** 2
        print(f'    fibre {modulus:8.2g} Pa (EA {ea:7.3f} N): least twist '
              f'stability {least:+.2e} N m/rad^2, {np.sum(rows["twist_stability"][at] <= 0)} '
              f'of {at.sum()} fields twist it')
    fig.tight_layout()
    OUT.parent.mkdir(exist_ok=True)
    fig.savefig(OUT, dpi=90)
    print(f'wrote {OUT.relative_to(ROOT)}')


if __name__ == '__main__':
    main()
