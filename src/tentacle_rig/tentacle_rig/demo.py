"""
make demo: a whole navigation on the simulated rig, in three modes, reported.

Plans the pancreatic duct scene (or reuses out/schedule.yaml when it was planned from this
very scene file), and the tip-driven baseline likewise (out/tip_driven/schedule.yaml), then
plays each mode on the simulated rig with the scene's stated mismatch (a rig unlike the
model: softer, weaker magnets, the insertion point and the coils off): shape forming open
loop, shape forming with the closed loop, tip-driven open loop. Each mode is a fresh rig
(scripts/rig's process table, a private device folder): home, the tracker's empty scene,
the run recorded. Writes into out/ as DESIGN.md says: schedule.yaml, report.json,
report.md, shapes_<mode>.png (desired against achieved, per step), shape_error.png and
recordings/<mode>/ (rosbag2, MCAP). Shape errors are measured on the truth (/sim/shape).
"""

import argparse
import json
import math
import pathlib
import shutil
import sys
import tempfile
import time

import numpy as np
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]
SCENE = ROOT / 'config' / 'scenes' / 'pancreatic_duct.yaml'
MODES = {  # mode: (which plan, the player's mode)
    'open_loop': ('shape_forming', 'open_loop'),
    'closed_loop': ('shape_forming', 'closed_loop'),
    'tip_driven': ('tip_driven', 'open_loop'),
}
RUN_TIMEOUT_S = 300.0


def say(line):
    """Print a progress line now."""
    print(f'demo: {line}', flush=True)


def cached_plan(scene, out_dir, tip_driven):
    """Return a schedule file for the scene: the one in out_dir if planned from this scene."""
    from tentacle_planner.errors import PlanInputError
    from tentacle_planner.schedule_file import read_schedule
    path = pathlib.Path(out_dir) / 'schedule.yaml'
    what = 'tip-driven baseline' if tip_driven else 'shape-forming plan'
    if path.is_file():
        try:
            schedule = read_schedule(path)
            if schedule.scene_sha256 == scene.sha256 and not schedule.interrupted:
                say(f'{what}: {path} (planned from this scene before)')
                return path
        except PlanInputError:
            pass
    from tentacle_planner.plan_plot import write_plot
    from tentacle_planner.planner import plan_scene
    from tentacle_planner.schedule_writer import write_schedule_file
    say(f'{what}: planning {scene.name} (a few seconds; cached in {path} for the next run)')
    started = time.monotonic()
    result = plan_scene(scene, tip_driven=tip_driven)
    written = write_schedule_file(out_dir, result)
    write_plot(out_dir, result)
    say(f'{what}: planned in {time.monotonic() - started:.0f} s'
        + (f', flags: {"; ".join(result.flags)}' if result.flags else ''))
    return written


def run_mode(mode, schedule, recording, logs):
    """
    Play a schedule on a fresh simulated rig in one mode, recorded; return the recording.

    :raises RuntimeError: the rig did not come up, refused, or the run did not finish
    """
    from tentacle_common import contract
    from tentacle_rig.bringup import Rig, sim_table
    from tentacle_rig.commander_node import RigCommander
    from tqdm import tqdm
    with tempfile.TemporaryDirectory(prefix='tentacle_demo_') as devices:
        table = sim_table(SCENE, ROOT, devices, schedule=schedule,
                          player={'mode': MODES[mode][1]}, record=recording)
        rig = Rig(table, logs / mode, ROOT, say=lambda line: None)
        try:
            with RigCommander(f'demo_{mode}') as commander:
                recorded = [contract.PLAYER_PROGRESS, contract.SIM_SHAPE, contract.FIELD_CMD]
                for step in (commander.wait_for_rig, commander.home,
                             commander.capture_background,
                             lambda: commander.wait_for_recorder(recorded)):
                    result = step()
                    if not result:
                        raise RuntimeError(f'{mode}: {result.message}')
                count = len(yaml.safe_load(pathlib.Path(schedule).read_text())['steps'])
                with tqdm(total=count, desc=f'{mode:>11}', unit='step', ncols=80,
                          file=sys.stdout) as bar:
                    result = commander.play(
                        timeout_s=RUN_TIMEOUT_S,
                        on_progress=lambda p: bar.update(max(0, p.step - bar.n)))
                if not result:
                    raise RuntimeError(f'{mode}: the run ended {result.outcome.value}: '
                                       f'{result.message}')
        finally:
            report = rig.stop()
        unsafe = [name for name, _, _, safe in report if not safe]
        if unsafe:
            raise RuntimeError(f'{mode}: not confirmed safe at the end: {", ".join(unsafe)} '
                               f'(logs in {logs / mode})')
    return recording


def rig_step_time_s():
    """Return the rig's own time per 1 mm step, s: the stage's move and the player's dwell."""
    sim = ROOT / 'config' / 'sim'
    axis = yaml.safe_load((sim / 'inserter.yaml').read_text())['inserter_node']['ros__parameters']
    player = yaml.safe_load((sim / 'player.yaml').read_text())['player_node']['ros__parameters']
    speed, accel = axis['max_speed'], axis['acceleration']
    return 1e-3 / speed + speed / accel + player['dwell_s']


def summary(mode, steps, figures, recording, out):
    """Return a mode's report.json entry."""
    from tentacle_rig.run_report import mean_shape_rms
    durations = [s.duration_s for s in steps if s.duration_s is not None]
    return {
        'mean_shape_rms_m': mean_shape_rms(steps),
        'recording': str(pathlib.Path(recording).relative_to(out)),
        'steps': [s.row() for s in steps],
        'max_shape_rms_m': max((s.shape_rms_m for s in steps), default=math.nan),
        'contact_steps': sum(s.contact_depth_m > 0 for s in steps),
        'deepest_contact_m': max((s.contact_depth_m for s in steps), default=0.0),
        'step_time_median_s': float(np.median(durations)) if durations else math.nan,
        'overhead_per_step_median_s': (float(np.median(durations)) - rig_step_time_s())
        if durations else math.nan,
        'player': figures,
    }


def write_markdown(path, report, scene):
    """Write report.md: what was run, the table of modes, the key steps, the pictures."""
    modes = report['modes']
    lines = [f'# Navigation on the simulated rig: {scene.name}', '',
             f'Mismatch (the rig unlike the model): {report["mismatch"]}. Shape errors are '
             'measured on the simulated truth (/sim/shape) when each step ends, against the '
             "desired path (DESIGN.md's shape error).", '',
             '| mode | mean shape RMS | worst step | steps in contact (deepest) | step time '
             '(median) | software overhead per step | closed loop |',
             '| --- | --- | --- | --- | --- | --- | --- |']
    for mode, m in modes.items():
        loop = m['player']
        loop_text = (f'{loop.get("loop_rate_hz")} Hz, frame to command '
                     f'{loop.get("loop_latency_ms_median")} ms median '
                     f'({loop.get("loop_latency_ms_p95")} ms p95), '
                     f'{loop.get("loop_corrections")} corrections') \
            if mode == 'closed_loop' else '-'
        lines.append(f'| {mode} | {m["mean_shape_rms_m"] * 1e3:.3f} mm | '
                     f'{m["max_shape_rms_m"] * 1e3:.3f} mm | {m["contact_steps"]} '
                     f'({m["deepest_contact_m"] * 1e3:.2f} mm) | '
                     f'{m["step_time_median_s"] * 1e3:.0f} ms | '
                     f'{m["overhead_per_step_median_s"] * 1e3:.0f} ms | {loop_text} |')
    lines += ['', "The rig's own time per 1 mm step (the stage's move and the dwell) is "
              f'{rig_step_time_s() * 1e3:.0f} ms; the overhead is the median step time beyond '
              'it (in closed loop it includes the corrections).', '',
              '| inserted | ' + ' | '.join(modes) + ' |',
              '| --- |' + ' --- |' * len(modes)]
    by_step = {mode: {round(r['insertion_m'] * 1e3): r for r in m['steps']}
               for mode, m in modes.items()}
    for mm in sorted({k for rows in by_step.values() for k in rows if k % 10 == 0}):
        cells = [f'{rows[mm]["shape_rms_m"] * 1e3:.3f} mm' if mm in rows else '-'
                 for rows in by_step.values()]
        lines.append(f'| {mm} mm | ' + ' | '.join(cells) + ' |')
    lines += ['', '![shape error per step](shape_error.png)', '']
    lines += [f'![{mode}](shapes_{mode}.png)' for mode in modes]
    lines += ['', 'Recordings (rosbag2, MCAP; Foxglove opens them): '
              + ', '.join(f'`{m["recording"]}`' for m in modes.values()), '']
    path.write_text('\n'.join(lines))


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='demo', description=__doc__.strip().split('\n')[0])
    parser.add_argument('--out', default=str(ROOT / 'out'), help='where the outputs go')
    parser.add_argument('--modes', default=','.join(MODES),
                        help=f'comma-separated, of {", ".join(MODES)}')
    return parser


def main(args=None):
    """Plan, run every mode, write the report; return the exit code."""
    opts = build_parser().parse_args(args)
    modes = [m for m in opts.modes.split(',') if m]
    unknown = [m for m in modes if m not in MODES]
    if unknown:
        print(f'demo: unknown modes {unknown}: of {", ".join(MODES)}', file=sys.stderr)
        return 2
    from tentacle_planner import paths
    from tentacle_planner.scene import load_scene
    from tentacle_rig.recording import read_bag
    from tentacle_rig.report_plot import plot_errors, plot_shapes
    from tentacle_rig.run_report import loop_figures, steps_of
    started = time.monotonic()
    out = pathlib.Path(opts.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = load_scene(SCENE)
    plans = {'shape_forming': cached_plan(scene, out, False)}
    if any(MODES[m][0] == 'tip_driven' for m in modes):
        plans['tip_driven'] = cached_plan(scene, out / 'tip_driven', True)
    stamp = time.strftime('%Y%m%d-%H%M%S')
    logs = pathlib.Path(tempfile.gettempdir()) / 'tentacle_demo' / stamp
    path = paths.Path(scene.path.points_m, str(SCENE))
    report = {'scene': scene.name, 'mismatch': scene.mismatch.describe(), 'modes': {}}
    outcomes = {}
    for mode in modes:
        recording = out / 'recordings' / mode
        shutil.rmtree(recording, ignore_errors=True)   # the previous demo's
        say(f'{mode}: a fresh simulated rig (logs in {logs / mode})')
        run_mode(mode, plans[MODES[mode][0]], recording, logs)
        bag = read_bag(recording)
        outcomes[mode] = steps_of(bag, path)
        report['modes'][mode] = summary(mode, outcomes[mode], loop_figures(bag), recording, out)
        plot_shapes(out / f'shapes_{mode}.png', mode, outcomes[mode], path, scene)
        say(f'{mode}: mean shape RMS {report["modes"][mode]["mean_shape_rms_m"] * 1e3:.3f} mm '
            f'over {len(outcomes[mode])} steps; recorded in {recording}')
    plot_errors(out / 'shape_error.png', outcomes)
    (out / 'report.json').write_text(json.dumps(report, indent=1))
    write_markdown(out / 'report.md', report, scene)
    say(f'done in {time.monotonic() - started:.0f} s: {out / "report.md"}')
    return 0
