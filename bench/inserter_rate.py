#!/usr/bin/env python3
"""
Benchmark: how fast the inserter answers a target and how often it can step 1 mm.

Against the stage emulators over real ptys (tentacle_sim.stage_emulator), through the axis
worker the node uses (tentacle_inserter.axis_worker), in this process: the latency from a
target handed over to the emulated axis starting to move (median and p95 of 20), and the
rate of 1 mm moves, each followed by a settle time for the field (0.1 s), for both
dialects. The thesis rig ran 1 mm steps at 2 Hz (5.3.3); the ratio to that is printed. The
cross-process latency through DDS (inserter_node) is not measured here yet.

Run: .venv/bin/python bench/inserter_rate.py
"""

import pathlib
import statistics
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]

from tentacle_common.serial_line import SerialLine  # noqa: E402
from tentacle_inserter import stage  # noqa: E402
from tentacle_inserter.axis_worker import AxisWorker  # noqa: E402
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


def rig(dialect, folder):
    """Return (emulator, started worker) for a dialect."""
    link = str(pathlib.Path(folder) / dialect)
    if dialect == 'gcode':
        emu = GcodeStage('e', link_path=link, accel_m_s2=ACCEL_M_S2).start()
        axis = stage.GcodeStage(SerialLine(link, 115200), max_length_m=0.1,
                                max_speed_m_s=SPEED_M_S, accel_m_s2=ACCEL_M_S2,
                                steps_per_mm=100.0, reply_timeout_s=0.2)
    else:
        emu = Step1mmStage('e', link_path=link, speed_m_s=SPEED_M_S,
                           accel_m_s2=ACCEL_M_S2).start()
        axis = stage.Step1mmStage(SerialLine(link, 9600), max_length_m=0.1)
    worker = AxisWorker(axis).start()
    wait_for(lambda: worker.connected)
    worker.home()
    return emu, worker


def measure(dialect, folder):
    """Return (latencies s, 1 mm moves per second with the settle time)."""
    emu, worker = rig(dialect, folder)
    try:
        latencies, position = [], 0.0
        for _ in range(20):
            position += 0.001
            t0 = time.monotonic()
            worker.set_target(position)
            started = wait_for(lambda: emu.state()['moving'])
            latencies.append(started - t0)
            wait_for(lambda: not emu.state()['busy'] and abs(
                emu.state()['position_m'] - position) < 1e-6)
        t0 = time.monotonic()
        for _ in range(10):
            position += 0.001
            worker.set_target(position)
            wait_for(lambda: emu.state()['moving'])
            wait_for(lambda: not emu.state()['busy'] and abs(
                emu.state()['position_m'] - position) < 1e-6)
            time.sleep(SETTLE_S)
        rate = 10 / (time.monotonic() - t0)
        return latencies, rate
    finally:
        worker.shutdown()
        emu.stop()


def main():
    """Measure both dialects and print the table."""
    print(f'1 mm moves at {SPEED_M_S * 1e3:g} mm/s, {ACCEL_M_S2:g} m/s^2, '
          f'{SETTLE_S * 1e3:g} ms settle between moves')
    print('  dialect   latency median   p95      1 mm moves/s   vs thesis 2 Hz')
    with tempfile.TemporaryDirectory() as folder:
        for dialect in ('gcode', 'step1mm'):
            latencies, rate = measure(dialect, folder)
            ordered = sorted(latencies)
            p95 = ordered[int(0.95 * (len(ordered) - 1))]
            print(f'  {dialect:8s}  {statistics.median(latencies) * 1e3:8.2f} ms  '
                  f'{p95 * 1e3:8.2f} ms  {rate:10.2f}      {rate / THESIS_HZ:5.2f}x')


if __name__ == '__main__':
    main()
