#!/usr/bin/env python3
"""
Demo: three emulated DXKDP supplies, coils_node, and a rotating field.

Brings up the rig exactly as a lab would run it (coils_node in its own process with
config/coils.yaml, the supplies on serial lines, 9600 baud), commands a 10 mT field
rotating in the x-y plane over a constant 3 mT on z, and prints per axis what the supplies
were told and what they measured, then writes a plot. Stops everything at the end, leaving
the supplies at zero and off.
"""

import argparse
import os
import pathlib
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
SOURCES = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]
sys.path[:0] = SOURCES
os.environ['PYTHONPATH'] = os.pathsep.join(SOURCES + [os.environ.get('PYTHONPATH', '')])
os.environ.setdefault('ROS_DOMAIN_ID', str(200 + os.getpid() % 30))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import numpy as np  # noqa: E402

from tentacle_coils.field_map import ActuationMap  # noqa: E402
from tentacle_coils.params import REFERENCE_MATRIX_T_PER_A  # noqa: E402
from tentacle_common import contract  # noqa: E402
from tentacle_common.waiting import wait_for  # noqa: E402
from tentacle_rig.commander_node import RigCommander  # noqa: E402
from tentacle_sim.sim_rig import CoilRig  # noqa: E402


def field_at(t, amplitude_t, period_s, z_t):
    """Return the commanded field (T) at time t: rotating in x-y, constant on z."""
    phase = 2 * np.pi * t / period_s
    return np.array([amplitude_t * np.cos(phase), amplitude_t * np.sin(phase), z_t])


def main():
    """Run the demo; return the process exit code."""
    parser = argparse.ArgumentParser(description=__doc__.strip().split('\n')[0])
    parser.add_argument('--seconds', type=float, default=6.0, help='how long to rotate')
    parser.add_argument('--rate', type=float, default=20.0, help='field commands per second')
    parser.add_argument('--amplitude-mt', type=float, default=10.0)
    parser.add_argument('--period-s', type=float, default=3.0)
    parser.add_argument('--out', default=str(ROOT / 'bench' / 'out'),
                        help='where to write demo_coils.png')
    opts = parser.parse_args()
    amap = ActuationMap(REFERENCE_MATRIX_T_PER_A)
    workdir = tempfile.mkdtemp(prefix='tentacle_demo_')
    print(f'demo: starting 3 emulated DXKDP supplies (9600 baud) and coils_node; '
          f'logs in {workdir}', flush=True)
    rig = CoilRig(workdir, ROOT / 'config' / 'coils.yaml', 'dxkdp', 9600, cwd=ROOT)
    commander = RigCommander('coils_demo', axes=())   # the lab's facade
    commander.follow('currents', contract.CURRENTS)
    rows = []
    try:
        up = commander.wait_for_coils(20.0)
        if not (up and wait_for(lambda: all(rig.emulators.outputs()), 10.0)):
            print(f'demo: coils_node did not come up ({up.message}); its log:\n'
                  + rig.node.output())
            return 1
        print(f'demo: rotating {opts.amplitude_mt:g} mT in x-y (period {opts.period_s:g} s) '
              f'over 3 mT on z, {opts.rate:g} commands/s for {opts.seconds:g} s\n')
        header = (f'{"t s":>5} | {"commanded mT":^20} | {"told supplies A":^22} | '
                  f'{"measured A":^22} | {"field from measured mT":^22}')
        print(header + '\n' + '-' * len(header))
        t0 = time.monotonic()
        next_print = 0.0
        while (t := time.monotonic() - t0) < opts.seconds:
            field = field_at(t, opts.amplitude_mt * 1e-3, opts.period_s, 3e-3)
            commander.send_field(field)   # a stream: each command renews the last
            time.sleep(max(0.0, t0 + t + 1.0 / opts.rate - time.monotonic()))
            told = rig.emulators.setpoints()
            cur, fld = commander.latest('currents'), commander.latest('field')
            measured = [cur.vector.x, cur.vector.y, cur.vector.z] if cur else [np.nan] * 3
            made = [fld.vector.x, fld.vector.y, fld.vector.z] if fld else [np.nan] * 3
            rows.append([t, *field, *told, *measured, *made])
            if t >= next_print:
                next_print += 0.5
                fmt = ' '.join(f'{v:6.2f}' for v in field * 1e3)
                print(f'{t:5.2f} | {fmt} | ' + ' '.join(f'{v:6.2f}' for v in told) + ' | '
                      + ' '.join(f'{v:6.2f}' for v in measured) + ' | '
                      + ' '.join(f'{v * 1e3:6.2f}' for v in made), flush=True)
        data = np.array(rows)
        hold = field_at(opts.seconds, opts.amplitude_mt * 1e-3, opts.period_s, 3e-3)
        settled = hold_and_measure(commander, hold)
        summarise(data, amap, rig, hold, settled)
        plot(data, amap, pathlib.Path(opts.out))
        return 0
    finally:
        commander.close()
        code = rig.node.stop()
        state = rig.emulators.state()
        rig.emulators.stop()
        print(f'\ndemo: coils_node exited with {code}; supplies now: ' + ', '.join(
            f"{n} {state[n]['setpoint_a']:.2f} A, output "
            f"{'on' if state[n]['output_on'] else 'off'}"
            for n in 'xyz'))


def hold_and_measure(commander, field):
    """Hold one field for a second; return the field made by the measured currents (T)."""
    commander.set_field(field, timeout_s=2.0)
    time.sleep(1.0)
    made = commander.field_t()
    commander.release_field()
    return made


def summarise(data, amap, rig, hold, settled):
    """Print per-axis set counts and how well the field follows."""
    t, commanded, told, made = data[:, 0], data[:, 1:4], data[:, 4:7], data[:, 10:13]
    moving = t > 0.5  # after the first ramp up at the slew limit
    # A row's command was published one period before the supplies were read.
    expected = np.array([amap.currents(b) for b in commanded])
    counts = {n: len(rig.emulators.sets_since(0.0)[n]) for n in 'xyz'}
    rows = [('set commands received', [f'{counts[n]:d}' for n in 'xyz']),
            ('max |told - A^-1 B_cmd| (A)',
             [f'{v:.3f}' for v in np.max(np.abs(told - expected)[moving], axis=0)]),
            ('median |B_meas - B_cmd| moving (mT)',
             [f'{v:.3f}' for v in np.nanmedian(np.abs(made - commanded)[moving], axis=0) * 1e3]),
            ('|B_meas - B_cmd| held 1 s (mT)',
             [f'{v:.4f}' for v in np.abs(settled - hold) * 1e3])]
    print(f'\n{"per axis":38}{"x":>9}{"y":>9}{"z":>9}')
    for label, values in rows:
        print(f'{label:38}' + ''.join(f'{v:>9}' for v in values))
    print('(a moving field is measured up to one readback period late: publish_rate 10 Hz)')


def plot(data, amap, out_dir):
    """Write commanded, told and measured field per axis to demo_coils.png."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    out_dir.mkdir(parents=True, exist_ok=True)
    told_field = np.array([amap.field(i) for i in data[:, 4:7]])
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 6))
    for i, (ax, name) in enumerate(zip(axes, 'xyz')):
        ax.plot(data[:, 0], data[:, 1 + i] * 1e3, label='commanded')
        ax.plot(data[:, 0], told_field[:, i] * 1e3, '--', label='setpoints held by supplies')
        ax.plot(data[:, 0], data[:, 10 + i] * 1e3, '.', ms=3, label='from measured currents')
        ax.set_ylabel(f'B{name} (mT)')
    axes[0].legend(loc='upper right')
    axes[-1].set_xlabel('time (s)')
    fig.suptitle('coils_node demo: rotating field, 3 emulated DXKDP supplies at 9600 baud')
    fig.tight_layout()
    path = out_dir / 'demo_coils.png'
    fig.savefig(path, dpi=100)
    print(f'plot: {path}')


if __name__ == '__main__':
    sys.exit(main())
