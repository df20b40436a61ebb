#!/usr/bin/env python3
"""
Benchmark: how fast the inserter answers a target and how often it can step 1 mm.

Against the stage emulators over real ptys (tentacle_sim.stage_emulator), through the axis
worker the node uses (tentacle_inserter.axis_worker), in this process: the latency from a
target handed to an idle axis to the emulated axis starting to move (median and p95 of 20),
and the
rate of 1 mm moves, each followed by a settle time for the field (0.1 s), for both
dialects; then the same through DDS: a target published on /inserter/target to a running
inserter_node (its axis in a child process of its own) until the emulated axis moves. The
thesis rig ran 1 mm steps at 2 Hz (5.3.3); the ratio to that is printed.

Run: .venv/bin/python bench/inserter_rate.py
"""

import os
import pathlib
import statistics
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
SOURCES = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]
sys.path[:0] = SOURCES
os.environ['PYTHONPATH'] = os.pathsep.join(SOURCES + [os.environ.get('PYTHONPATH', '')])
# A domain of its own, on this machine only, so a bench never talks to a running rig.
os.environ.setdefault('ROS_DOMAIN_ID', str(226 + os.getpid() % 2))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

import rclpy  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from tentacle_common import contract  # noqa: E402
from tentacle_common.driver_node import client, publisher  # noqa: E402
from tentacle_common.serial_line import SerialLine  # noqa: E402
from tentacle_inserter import stage  # noqa: E402
from tentacle_inserter.axis_worker import AxisWorker  # noqa: E402
from tentacle_sim.sim_rig import NodeProcess  # noqa: E402
from tentacle_sim.stage_emulator import GcodeStage, Step1mmStage  # noqa: E402

SPEED_M_S, ACCEL_M_S2, SETTLE_S, THESIS_HZ = 0.01, 0.5, 0.1, 2.0


def wait_for(condition, timeout_s=5.0):
    """Return the time condition() became true (monotonic s), or None."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return time.monotonic()
        time.sleep(0.0005)
    return None


def emulator(dialect, link):
    """Return a started stage emulator for a dialect."""
    if dialect == 'gcode':
        return GcodeStage('e', link_path=link, accel_m_s2=ACCEL_M_S2).start()
    return Step1mmStage('e', link_path=link, speed_m_s=SPEED_M_S,
                        accel_m_s2=ACCEL_M_S2).start()


def in_process(dialect, link):
    """Return (send a target, close) through an AxisWorker in this process, homed."""
    line = SerialLine(link, 115200 if dialect == 'gcode' else 9600)
    if dialect == 'gcode':
        axis = stage.GcodeStage(line, max_length_m=0.1, max_speed_m_s=SPEED_M_S,
                                accel_m_s2=ACCEL_M_S2, steps_per_mm=100.0, reply_timeout_s=0.2)
    else:
        axis = stage.Step1mmStage(line, max_length_m=0.1, speed_m_s=SPEED_M_S,
                                  accel_m_s2=ACCEL_M_S2)
    worker = AxisWorker(axis).start()
    wait_for(lambda: worker.connected)
    worker.home()
    return worker.set_target, worker.shutdown


def through_dds(dialect, link, folder):
    """Return (send a target, close) through inserter_node in its own process, homed."""
    argv = [sys.executable, '-m', 'tentacle_inserter.inserter_node', '--ros-args',
            '-p', f'port:={link}', '-p', f'dialect:={dialect}', '-p', 'max_length:=0.1',
            '-p', f'max_speed:={SPEED_M_S}', '-p', f'acceleration:={ACCEL_M_S2}',
            '-p', f'baud:={115200 if dialect == "gcode" else 9600}']
    node = NodeProcess(argv, str(pathlib.Path(folder) / f'{dialect}_node.log'))
    probe = rclpy.create_node('inserter_bench')
    targets = publisher(probe, contract.axis_target('inserter'))
    home = client(probe, contract.axis_service('inserter', 'home'))
    if not home.wait_for_service(timeout_sec=30.0):
        raise RuntimeError(f'inserter_node did not come up:\n{node.output()}')
    future = home.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(probe, future, timeout_sec=20.0)
    while targets.get_subscription_count() == 0:
        rclpy.spin_once(probe, timeout_sec=0.05)

    def close():
        probe.destroy_node()
        node.stop()
    return (lambda target_m: targets.publish(Float64(data=target_m))), close


def measure(emu, send):
    """Return (latencies s, 1 mm moves per second with the settle time)."""
    def reached(position):
        return wait_for(lambda: not emu.state()['busy'] and abs(
            emu.state()['position_m'] - position) < 1e-6)
    latencies, position = [], 0.0
    for _ in range(20):
        position += 0.001
        t0 = time.monotonic()
        send(position)
        latencies.append(wait_for(lambda: emu.state()['moving']) - t0)
        reached(position)
        time.sleep(SETTLE_S)  # the next target finds the axis idle, as after a field settle
    t0 = time.monotonic()
    for _ in range(10):
        position += 0.001
        send(position)
        wait_for(lambda: emu.state()['moving'])
        reached(position)
        time.sleep(SETTLE_S)
    return latencies, 10 / (time.monotonic() - t0)


def main():
    """Measure both dialects, in process and through DDS, and print the table."""
    print(f'1 mm moves at {SPEED_M_S * 1e3:g} mm/s, {ACCEL_M_S2:g} m/s^2, '
          f'{SETTLE_S * 1e3:g} ms settle between moves; latency: target to motion')
    print('  dialect   path          latency median   p95      1 mm moves/s   vs thesis 2 Hz')
    rclpy.init()
    try:
        with tempfile.TemporaryDirectory() as folder:
            for dialect in ('gcode', 'step1mm'):
                for path in ('in process', 'DDS, 2 proc'):
                    link = str(pathlib.Path(folder) / dialect)
                    emu = emulator(dialect, link)
                    send, close = (in_process(dialect, link) if path == 'in process'
                                   else through_dds(dialect, link, folder))
                    try:
                        latencies, rate = measure(emu, send)
                    finally:
                        close()
                        emu.stop()
                    ordered = sorted(latencies)
                    p95 = ordered[int(0.95 * (len(ordered) - 1))]
                    print(f'  {dialect:8s}  {path:12s}  {statistics.median(latencies) * 1e3:8.2f}'
                          f' ms  {p95 * 1e3:8.2f} ms  {rate:10.2f}      '
                          f'{rate / THESIS_HZ:5.2f}x', flush=True)
    finally:
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
