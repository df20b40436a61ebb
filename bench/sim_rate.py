#!/usr/bin/env python3
"""
Benchmark: the simulated rig with the full stack on this machine.

The rig as scripts/rig starts it (the bringup's process table: sim_node, coils_node,
inserter_node, tracker_node, each its own process) on a scene (default the pancreatic duct:
the braided 3-DoF tentacle, 50 mm inserted) at 2048 x 1536 mono8 and 30 Hz. After the body is
inserted (and a backbone at its scene's first step), field steps alternate between two
fields, every 2 s over a window for the rates and CPU, then one by one for the lag (this
probe no longer taking the frames); the figures:

- frames per second sustained: /sim/shape and /camera/image_raw as received, /vision/tip as
  tracked, over the measuring window;
- physics and render time per frame: sim_node's own (its diagnostics, over its last 300);
- lag from a supply's current change to the /sim/shape that shows it: the supply's output
  polled over the control socket every 2 ms until it moves, to the receipt of the first
  shape sampled after that (its stamp; target: at most two frame periods), and to the first
  whose tip moved more than 0.1 mm (the supplies still slewing: what a camera would see);
- CPU share of each node with its child processes, in cores, from /proc over the window.

Run: .venv/bin/python bench/sim_rate.py [--scene FILE] [--steps N] [--window-s S]
(writes bench/out/sim_rate.json)
"""

import argparse
import json
import os
import pathlib
import statistics
import sys
import tempfile
import threading
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
SOURCES = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]
sys.path[:0] = SOURCES
os.environ['PYTHONPATH'] = os.pathsep.join(SOURCES + [os.environ.get('PYTHONPATH', '')])
os.environ.setdefault('ROS_DOMAIN_ID', str(228 + os.getpid() % 2))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from geometry_msgs.msg import Vector3Stamped  # noqa: E402
import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from tentacle_common import contract  # noqa: E402
from tentacle_common.child_process import child_pids  # noqa: E402
from tentacle_common.driver_node import client, publisher, subscription  # noqa: E402
from tentacle_common.waiting import wait_for  # noqa: E402
from tentacle_planner.scene import load_scene  # noqa: E402
from tentacle_rig.bringup import Rig, sim_table  # noqa: E402
from tentacle_sim.sim_devices import ask  # noqa: E402

FIELDS_T = ([0.0, 0.010, 0.0], [0.008, -0.004, 0.0])


def cpu_s(pid):
    """Return the user + system CPU time of a process and the ones it started, s (/proc)."""
    fields = pathlib.Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    own = (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    return own + sum(cpu_s(child) for child in child_pids(pid))


class Probe:
    """Subscriptions counted and kept, publishers for the field and the inserter."""

    def __init__(self):
        rclpy.init()
        self.node = rclpy.create_node('sim_rate_bench')
        self.lock = threading.Lock()
        self.times = {'shape': [], 'image': [], 'tip': []}
        self.shapes, self.diagnostics = [], []
        subscription(self.node, contract.SIM_SHAPE, self._shape)
        self.images = subscription(self.node, contract.IMAGE, lambda m: self._count('image'))
        subscription(self.node, contract.VISION_TIP, lambda m: self._count('tip'))
        subscription(self.node, contract.DIAGNOSTICS, self._diagnostics)
        self.field = publisher(self.node, contract.FIELD_CMD)
        self.targets = {axis: publisher(self.node, contract.axis_target(axis))
                        for axis in contract.AXES}
        self.homes = {axis: client(self.node, contract.axis_service(axis, 'home'))
                      for axis in contract.AXES}
        self.background = client(self.node, contract.VISION_CAPTURE_BACKGROUND)
        threading.Thread(target=rclpy.spin, args=(self.node,), daemon=True).start()

    def _count(self, key):
        with self.lock:
            self.times[key].append(time.monotonic())

    def _shape(self, msg):
        tip = msg.poses[-1].pose.position
        with self.lock:
            self.times['shape'].append(time.monotonic())
            self.shapes.append((time.monotonic(), np.array([tip.x, tip.y, tip.z]),
                                msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec))

    def _diagnostics(self, msg):
        for status in msg.status:
            if status.name == 'sim_node: world':
                with self.lock:
                    self.diagnostics.append({v.key: v.value for v in status.values})

    def command(self, field_t):
        msg = Vector3Stamped()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.header.frame_id = contract.COILS_FRAME
        msg.vector.x, msg.vector.y, msg.vector.z = field_t
        self.field.publish(msg)

    def rate(self, key, since, until):
        with self.lock:
            n = sum(since <= t < until for t in self.times[key])
        return n / (until - since)

    def last_tip(self):
        with self.lock:
            return self.shapes[-1][1] if self.shapes else None


def step_lag(probe, devices, field_t, before_a):
    """
    Command a field; return two lags (s) from the supplies' change, or None.

    To the receipt of the first shape sampled after the change, and of the first whose tip
    moved 0.1 mm.
    """
    tip_before = probe.last_tip()
    probe.command(field_t)
    changed = None   # (monotonic, wall clock) when a supply's output was seen to move
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        currents = [s['current_a'] for s in ask(devices, {'op': 'state'}).values()
                    if 'current_a' in s]
        if np.max(np.abs(np.array(currents) - before_a)) > 0.05:
            changed = time.monotonic(), time.time()
            break
        time.sleep(0.002)
    if changed is None:
        return None

    def first(condition):
        found = [t for t, tip, stamp in list(probe.shapes) if condition(t, tip, stamp)]
        return min(found) - changed[0] if found else None
    sampled = lambda t, tip, stamp: stamp >= changed[1]  # noqa: E731
    moved = lambda t, tip, stamp: t >= changed[0] and np.linalg.norm(  # noqa: E731
        tip - tip_before) > 1e-4
    if not wait_for(lambda: first(sampled) is not None and first(moved) is not None, 5.0):
        return None
    return first(sampled), first(moved)


def main():
    """Bring the rig up, insert, measure, print and write the figures."""
    parser = argparse.ArgumentParser(description=__doc__.strip().split('\n')[0])
    parser.add_argument('--scene', default=str(ROOT / 'config/scenes/pancreatic_duct.yaml'))
    parser.add_argument('--steps', type=int, default=10, help='field steps for the lag')
    parser.add_argument('--window-s', type=float, default=20.0, help='rate window, s')
    parser.add_argument('--inserted-m', type=float, default=0.05)
    opts = parser.parse_args()
    work = pathlib.Path(tempfile.mkdtemp(prefix='sim_rate_'))
    devices = work / 'devices'
    rig = Rig(sim_table(opts.scene, ROOT, devices), work / 'logs', ROOT)
    probe = Probe()
    try:
        scene = load_scene(opts.scene)
        # A backbone scene starts with the backbone at its first step (without it, a coiling
        # tentacle's own magnets curl it up into contact, which the model does not resolve).
        moves = {'inserter': opts.inserted_m}
        if scene.backbone_steps_m:
            moves['backbone'] = scene.backbone_steps_m[0]
        assert probe.background.wait_for_service(timeout_sec=30.0)
        assert wait_for(lambda: (f := probe.background.call_async(Trigger.Request()))
                        and wait_for(f.done, 5.0) and f.result().success, 30.0)
        for axis, position in moves.items():
            assert probe.homes[axis].wait_for_service(timeout_sec=30.0)
            future = probe.homes[axis].call_async(Trigger.Request())
            assert wait_for(future.done, 20.0) and future.result().success
            probe.targets[axis].publish(Float64(data=position))
            print(f'{axis} to {position * 1e3:g} mm ...', flush=True)
        assert wait_for(lambda: all(ask(devices, {'op': 'state'})[axis]['position_m']
                                    >= position - 1e-5 for axis, position in moves.items()),
                        60.0)
        probe.command(FIELDS_T[0])
        time.sleep(2.0)
        pids = {e.name: p.popen.pid for e, p in rig.processes}
        emulator_note = ('each node with the processes it started (the coil bank, the axis '
                         'process and their spares); the emulated devices run inside sim_node')
        cpu0 = {n: cpu_s(pid) for n, pid in pids.items()}
        t0 = time.monotonic()
        for k in range(int(opts.window_s // 2)):   # the rates: a field step every 2 s
            probe.command(FIELDS_T[k % 2])
            time.sleep(2.0)
        t1 = time.monotonic()
        cpu = {n: round((cpu_s(pid) - cpu0[n]) / (t1 - t0), 3) for n, pid in pids.items()}
        # The lags without the frames coming here: 3 MB a frame through this Python process
        # would hold up its receipt of the shapes, and time this probe, not the rig.
        probe.node.destroy_subscription(probe.images)
        lags, moved = [], []
        for k in range(opts.steps):
            before = np.array([s['current_a'] for s in ask(devices, {'op': 'state'}).values()
                               if 'current_a' in s])
            lag = step_lag(probe, devices, FIELDS_T[(k + 1) % 2], before)
            if lag is not None:
                lags.append(lag[0])
                moved.append(lag[1])
            time.sleep(1.5)
        diagnostics = probe.diagnostics[-1] if probe.diagnostics else {}
        figures = {
            'scene': pathlib.Path(opts.scene).name, 'image': '2048 x 1536 mono8',
            'window_s': round(t1 - t0, 1),
            'shape_hz': round(probe.rate('shape', t0, t1), 2),
            'image_hz': round(probe.rate('image', t0, t1), 2),
            'tip_hz': round(probe.rate('tip', t0, t1), 2),
            'sim_rate_hz': diagnostics.get('rate_hz'),
            'physics_ms_median': diagnostics.get('physics_ms_median'),
            'physics_ms_p95': diagnostics.get('physics_ms_p95'),
            'render_ms_median': diagnostics.get('render_ms_median'),
            'lag_ms_median': round(1e3 * statistics.median(lags), 1) if lags else None,
            'lag_ms_max': round(1e3 * max(lags), 1) if lags else None,
            'lag_to_0_1_mm_ms_median': round(1e3 * statistics.median(moved), 1) if moved
            else None,
            'lag_to_0_1_mm_ms_max': round(1e3 * max(moved), 1) if moved else None,
            'lag_steps': len(lags), 'two_frame_periods_ms': round(2e3 / 30.0, 1),
            'cpu_cores': cpu, 'cpu_note': emulator_note}
    finally:
        probe.node.destroy_node()
        rclpy.try_shutdown()
        rig.stop()
    out = ROOT / 'bench' / 'out'
    out.mkdir(exist_ok=True)
    (out / 'sim_rate.json').write_text(json.dumps(figures, indent=2))
    print(json.dumps(figures, indent=2))


if __name__ == '__main__':
    main()
