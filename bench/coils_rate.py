#!/usr/bin/env python3
"""
Benchmark: command-to-wire latency and sustained field update rate of coils_node.

The rig is as deployed: coils_node in its own process, three emulated supplies on ptys that
count a request as arrived only when its bytes would have crossed the line at the baud rate
(10 bits per byte). For dxkdp at 9600 baud and scpi at 115200 baud it measures

- latency: a field command published (time.monotonic) to the last byte of the matching set
  command arriving at the emulator, for the slowest of the three axes; median and p99 over
  commands sent at 20 Hz, beside the set command's own wire time;
- sustained rate: field commands published faster than the line can carry; set commands
  arriving per second on each axis (the field update rate is the slowest axis), beside the
  line-rate ceiling (one set command and its reply per axis) and the 5 commands per second of
  the known driver for these supplies (it sleeps 200 ms per command).

The emulated devices answer with no processing delay here (--delay-s 0): the ceiling is the
line's, so the figure measures the driver. The slew limit is raised out of the way (1e5 A/s)
so that each command's value goes out whole. Readbacks of measured current share the line;
the rate is measured at two readback rates (publish_rate).

Run: .venv/bin/python bench/coils_rate.py [--quick]   (writes bench/out/coils_rate.json)
"""

import argparse
import json
import os
import pathlib
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
SOURCES = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]
sys.path[:0] = SOURCES
os.environ['PYTHONPATH'] = os.pathsep.join(SOURCES + [os.environ.get('PYTHONPATH', '')])
os.environ.setdefault('ROS_DOMAIN_ID', str(230 + os.getpid() % 2))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from geometry_msgs.msg import Vector3Stamped  # noqa: E402
import numpy as np  # noqa: E402
import rclpy  # noqa: E402

from tentacle_coils.coil_bank import build_bank  # noqa: E402
from tentacle_coils.field_map import ActuationMap  # noqa: E402
from tentacle_coils.params import REFERENCE_MATRIX_T_PER_A  # noqa: E402
from tentacle_common import contract  # noqa: E402
from tentacle_common.driver_node import publisher  # noqa: E402
from tentacle_sim.emulator_client import EmulatorProcess  # noqa: E402
from tentacle_sim.sim_rig import CoilRig  # noqa: E402

KNOWN_DRIVER_RATE_HZ = 5.0  # 200 ms sleep per command
AMAP = ActuationMap(REFERENCE_MATRIX_T_PER_A)
STEP_A = 0.03  # distinct currents per command, three counts apart


class Commander:
    """Publishes field commands and spins for discovery."""

    def __init__(self):
        """Create the node and publisher."""
        self.node = rclpy.create_node('coils_bench')
        self.pub = publisher(self.node, contract.FIELD_CMD, contract.Qos(100))
        self.msg = Vector3Stamped()
        self.msg.header.frame_id = contract.COILS_FRAME

    def send(self, currents_a):
        """Publish the field that needs these currents; return the publish time (s)."""
        field = AMAP.field(currents_a)
        self.msg.vector.x, self.msg.vector.y, self.msg.vector.z = (float(v) for v in field)
        t = time.monotonic()
        self.pub.publish(self.msg)
        return t

    def wait_for_node(self, rig, timeout_s=20.0):
        """Wait until coils_node subscribes and has energised the outputs."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.05)
            if self.pub.get_subscription_count() and all(rig.emulators.outputs()):
                return
        raise RuntimeError('coils_node did not come up:\n' + rig.node.output())


class BankOnly:
    """The coil bank driven in-process (no DDS): what the driver can do by itself."""

    def __init__(self, workdir, dialect, baud):
        """Start emulators and a bank like coils_node's (readback 10 Hz, no slew limit)."""
        self.emulators = EmulatorProcess(pathlib.Path(workdir) / 'ports', dialect, baud,
                                         ['--delay-s', '0'], ROOT)
        self.bank = build_bank([self.emulators.ports[n] for n in 'xyz'], dialect=dialect,
                               baud=baud, max_current_a=60.0, slew_rate_a_per_s=1.0e5,
                               watchdog_s=10.0, readback_period_s=0.1)
        self.bank.start()
        deadline = time.monotonic() + 10.0
        while not (self.bank.connected() and self.bank.enable(True)[0]):
            if time.monotonic() > deadline:
                raise RuntimeError('supplies did not connect')
            time.sleep(0.01)

    def send(self, currents_a):
        """Command currents directly; return the time (s)."""
        t = time.monotonic()
        self.bank.command(currents_a)
        return t

    def stop(self):
        """Shut the bank down and stop the emulators."""
        self.bank.shutdown()
        self.emulators.stop()


def currents_for(k):
    """Return three distinct currents (A) for command k, alternating sign per axis."""
    base = 1.0 + STEP_A * (k % 400)
    return np.array([base, -base, base + 0.5])


def set_entries(rig, since):
    """Return {axis: (times (n,), currents (n,), request bytes (n,))} of set requests."""
    out = {}
    for axis in 'xyz':
        log = [e for e in rig.emulators.log(axis, since) if 'current_a' in e]
        out[axis] = (np.array([e['t'] for e in log]), np.array([e['current_a'] for e in log]),
                     np.array([len(e['hex']) // 2 for e in log]))
    return out


def measure_latency(rig, commander, count, rate_hz):
    """Return latencies (s) from publish to the last axis' set bytes arriving."""
    for k in range(10):  # warm up: DDS matching, first allocations (not measured)
        commander.send(currents_for(1000 + k))
        time.sleep(1.0 / rate_hz)
    time.sleep(0.2)
    t_start = time.monotonic()
    published = []
    for k in range(count):
        published.append(commander.send(currents_for(k)))
        time.sleep(max(0.0, published[-1] + 1.0 / rate_hz - time.monotonic()))
    time.sleep(0.3)
    entries = set_entries(rig, t_start)
    latencies = []
    for k, t_pub in enumerate(published):
        worst = 0.0
        for i, axis in enumerate('xyz'):
            times, values, _ = entries[axis]
            hit = np.nonzero((np.abs(values - currents_for(k)[i]) < STEP_A / 4)
                             & (times >= t_pub))[0]
            if len(hit) == 0:
                worst = np.nan
                break
            worst = max(worst, times[hit[0]] - t_pub)
        latencies.append(worst)
    return np.array(latencies), entries


def measure_rate(rig, commander, seconds, publish_hz):
    """
    Return set commands per second and mean set request bytes, each (3,), and offered /s.

    :param rig: has .emulators (a CoilRig, or BankOnly)
    :param commander: has .send(currents_a) (a Commander over DDS, or BankOnly)
    """
    t_start = time.monotonic()
    k = 0
    while time.monotonic() - t_start < seconds:
        commander.send(currents_for(k))
        k += 1
        time.sleep(max(0.0, t_start + k / publish_hz - time.monotonic()))
    t_end = time.monotonic()
    time.sleep(0.3)
    window = (t_start + 0.5, t_end)  # skip the start-up of the stream
    entries = set_entries(rig, window[0])
    rates, sizes = [], []
    for axis in 'xyz':
        times, _, nbytes = entries[axis]
        inside = (times >= window[0]) & (times <= window[1])
        rates.append(inside.sum() / (window[1] - window[0]))
        sizes.append(float(np.mean(nbytes[inside])))
    return np.array(rates), np.array(sizes), k / (t_end - t_start)


def run_dialect(dialect, baud, quick, workdir):
    """Measure one dialect; return a dict of figures."""
    reply_bytes = 1 if dialect == 'dxkdp' else 0  # SCPI set commands get no reply
    params = {'slew_rate': 1.0e5, 'watchdog_s': 10.0, 'max_current': 60.0, 'max_field': 0.05}
    figures = {'dialect': dialect, 'baud': baud}
    # Offer 25% more commands than the line carries (dxkdp set: 7 bytes; CURR x.xxxx: 12-13).
    offered_hz = 1.25 * baud / 10 / ((7 if dialect == 'dxkdp' else 13) + reply_bytes)
    commander = Commander()
    for readback_hz in (10.0, 2.0):
        run_dir = pathlib.Path(workdir) / f'{dialect}_{readback_hz:g}'
        run_dir.mkdir()
        rig = CoilRig(run_dir, ROOT / 'config' / 'coils.yaml', dialect, baud,
                      ['--delay-s', '0'], ROOT, publish_rate=readback_hz, **params)
        try:
            commander.wait_for_node(rig)
            if readback_hz == 10.0:
                latencies, entries = measure_latency(rig, commander, 60 if quick else 200,
                                                     20.0)
                request_bytes = float(np.mean(entries['x'][2]))
                figures.update({
                    'latency_median_ms': float(np.nanmedian(latencies) * 1e3),
                    'latency_p99_ms': float(np.nanpercentile(latencies, 99) * 1e3),
                    'latency_max_ms': float(np.nanmax(latencies) * 1e3),
                    'latency_missing': int(np.isnan(latencies).sum()),
                    'set_wire_time_ms': request_bytes * 10 / baud * 1e3})
            figures[f'rate_readback_{readback_hz:g}hz'] = rate_figures(
                *measure_rate(rig, commander, 2.0 if quick else 4.0, offered_hz), baud,
                reply_bytes)
        finally:
            code = rig.stop()
            if code != 0:
                print(f'warning: coils_node exited with {code}', file=sys.stderr)
    commander.node.destroy_node()
    run_dir = pathlib.Path(workdir) / f'{dialect}_bank_only'
    run_dir.mkdir()
    alone = BankOnly(run_dir, dialect, baud)
    try:
        figures['rate_bank_only'] = rate_figures(
            *measure_rate(alone, alone, 2.0 if quick else 4.0, offered_hz), baud, reply_bytes)
    finally:
        alone.stop()
    return figures


def rate_figures(rates, request_bytes, offered, baud, reply_bytes):
    """
    Return the rate figures beside the line-rate ceiling of one set and its reply.

    Each axis has its own line; its ceiling depends on its commands' length (a minus sign is
    one more SCPI byte). The field is updated as fast as its slowest axis.
    """
    ceilings = baud / 10 / (request_bytes + reply_bytes)
    return {'axes_per_s': rates.round(1).tolist(), 'axes_ceiling_per_s':
            ceilings.round(1).tolist(), 'field_updates_per_s': float(rates.min()),
            'offered_per_s': offered, 'ceiling_per_s': float(ceilings.min()),
            'fraction_of_ceiling': float(rates.min() / ceilings.min())}


def print_table(results):
    """Print the figures beside their references."""
    print('\ncoils_node command-to-wire latency (20 Hz commands; slowest of 3 axes)')
    print(f'{"dialect":>8} {"baud":>7} {"median ms":>10} {"p99 ms":>8} {"max ms":>8} '
          f'{"wire ms":>8} {"p99-wire":>9}  target p99-wire <= 5 ms')
    for r in results:
        print(f'{r["dialect"]:>8} {r["baud"]:>7} {r["latency_median_ms"]:10.2f} '
              f'{r["latency_p99_ms"]:8.2f} {r["latency_max_ms"]:8.2f} '
              f'{r["set_wire_time_ms"]:8.2f} '
              f'{r["latency_p99_ms"] - r["set_wire_time_ms"]:9.2f}'
              + (f'  ({r["latency_missing"]} not found)' if r['latency_missing'] else ''))
    print('\nsustained field update rate (commands offered faster than the line carries)')
    print(f'{"dialect":>8} {"baud":>7} {"readback":>9} {"offered":>8} {"x/s":>7} {"y/s":>7} '
          f'{"z/s":>7} {"field/s":>8} {"ceiling":>8} {"of ceil":>8} {"known drv":>10}')
    for r in results:
        for key in sorted(k for k in r if k.startswith('rate_')):
            s = r[key]
            hz = 'no DDS' if key == 'rate_bank_only' else key.split('_')[2]
            print(f'{r["dialect"]:>8} {r["baud"]:>7} {hz:>9} {s["offered_per_s"]:8.0f} '
                  + ''.join(f'{v:7.1f} ' for v in s['axes_per_s'])
                  + f'{s["field_updates_per_s"]:8.1f} {s["ceiling_per_s"]:8.1f} '
                  f'{100 * s["fraction_of_ceiling"]:7.1f}% {KNOWN_DRIVER_RATE_HZ:10.1f}')
    print('target: field/s >= 80% of the ceiling; the known driver manages 5 commands/s')
    print('"no DDS": the coil bank commanded in-process at 10 Hz readback, side by side: the\n'
          'driver alone, without the rclpy executor sharing its interpreter')


def main():
    """Run both dialects and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.strip().split('\n')[0])
    parser.add_argument('--quick', action='store_true', help='fewer samples (smoke run)')
    parser.add_argument('--out', default=str(ROOT / 'bench' / 'out' / 'coils_rate.json'))
    opts = parser.parse_args()
    rclpy.init()
    results = []
    try:
        with tempfile.TemporaryDirectory(prefix='coils_bench_') as workdir:
            for dialect, baud in (('dxkdp', 9600), ('scpi', 115200)):
                print(f'measuring {dialect} at {baud} baud ...', flush=True)
                results.append(run_dialect(dialect, baud, opts.quick, workdir))
    finally:
        rclpy.try_shutdown()
    print_table(results)
    out = pathlib.Path(opts.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    print(f'\nfigures: {out}')


if __name__ == '__main__':
    main()
