"""
Thesis chapter 6's coiling mode on the simulated rig, over DDS: coiled with feedback, released.

The first six backbone steps of config/scenes/ch6_coiling.yaml (the strip coiled to about
100 deg), played by player_node in ``coiling`` mode with the feedback ending at 60 deg (the
thesis: 220 deg of 360; here scaled to the short coil), so that the first steps are corrected
on the tracked tip angle and the last are open loop; then released by a retraction. Judged
on the simulator's truth in the rig's own recording, and on the emulators at the end.
"""

import math

import numpy as np
from plans import short_ch6
import pytest
from rig_support import ROOT, wait_for
from tentacle_common import contract
from tentacle_planner.shape_control import turning_rad
from tentacle_rig.bringup import Rig, sim_table, with_overrides
from tentacle_rig.commander_node import Outcome, RigCommander
from tentacle_rig.recording import read_bag
from tentacle_rig.run_report import points_of, step_spans
from tentacle_sim.sim_devices import ask
import yaml

pytestmark = pytest.mark.ros

FEEDBACK_MAX_DEG = 60.0
MISMATCH = {'remanence_factor': 0.75}   # weaker magnets than planned: the coil falls short
FAST = {'max_speed': 0.04}   # the 80 mm insertion in 2 s, not 16: the coil is what is tested


def turns_by_step(bag):
    """
    Return {step: the truth's turn at the step's end, deg} of the coiling run.

    Up to its last step, which runs on into the retraction's first (the same step index on
    /player/progress).
    """
    shapes = bag[contract.SIM_SHAPE.name]
    times = np.array([t for t, _ in shapes])
    spans = step_spans(bag[contract.PLAYER_PROGRESS.name])
    last = next(k for k, span in enumerate(spans) if span[0] == max(s[0] for s in spans))
    return {index: math.degrees(turning_rad(points_of(
        shapes[int(np.searchsorted(times, end)) - 1][1]))) for index, _, _, end in spans[:last]}


def corrections_by_step(bag):
    """
    Return the player's corrections counted by the coiling run, from its /diagnostics status.

    :return: ({step: the count when it first said the step}, the run's total)
    """
    first = {}
    for _, array in bag[contract.DIAGNOSTICS.name]:
        for status in (s for s in array.status if s.name == 'player_node: run'):
            values = {v.key: v.value for v in status.values}
            if values['phase'] == 'done':
                return first, int(values['loop_corrections'])
            if values['phase'] in ('moving', 'dwell'):
                first.setdefault(int(values['step']), int(values['loop_corrections']))
    raise AssertionError('the coiling run never said it was done')


def test_coiling_corrects_to_the_feedback_limit_then_open_loop_then_releases(tmp_path):
    scene, schedule = short_ch6(tmp_path, 6, MISMATCH)
    plan = yaml.safe_load(schedule.read_text())
    planned_deg = [math.degrees(turning_rad(np.array(s['predicted_centreline_m'])))
                   for s in plan['steps']]
    tentacle = tmp_path / 'made_to_plan.yaml'
    tentacle.write_text(yaml.safe_dump(plan['tentacle']))
    table = with_overrides(sim_table(
        scene, ROOT, tmp_path / 'devices', schedule=schedule, record=tmp_path / 'bag',
        player={'tentacle': tentacle, 'mode': 'coiling',
                'coil_feedback_max': math.radians(FEEDBACK_MAX_DEG),
                'stage_speed': FAST['max_speed']}),
        {'inserter_node': FAST, 'backbone_node': FAST})
    rig = Rig(table, tmp_path / 'logs', ROOT, say=lambda line: None)

    def supplies():
        state = ask(tmp_path / 'devices', {'op': 'state'})
        return [state[f'coil_{a}'] for a in 'xyz']
    try:
        with RigCommander('coiling_test', axes=('inserter', 'backbone')) as commander:
            for step in (commander.wait_for_rig, commander.wait_for_player,
                         commander.home, lambda: commander.home('backbone'),
                         commander.capture_background):
                assert step(), rig.process('player_node').output()[-3000:]
            coiled = commander.play(timeout_s=120.0)
            assert coiled.outcome is Outcome.DONE, coiled
            figures = commander.status('player_node: run').values
            released = commander.play(retract=True, timeout_s=120.0)
            assert released.outcome is Outcome.DONE, released
        # Read back from the emulators: the supplies at zero, nothing inserted.
        assert wait_for(lambda: all(abs(s['current_a']) < 1e-3 for s in supplies()), 10.0)
        stage = ask(tmp_path / 'devices', {'op': 'state'})['inserter']
        assert stage['position_m'] == pytest.approx(0.0, abs=2e-5) and not stage['moving']
    finally:
        report = rig.stop()
    assert all(safe for _, _, _, safe in report), report

    bag = read_bag(tmp_path / 'bag')
    turns = turns_by_step(bag)
    first, total = corrections_by_step(bag)
    # Corrected on the tracked tip angle while the plan turns at most 60 deg (steps 1-3) ...
    assert [planned_deg[k - 1] <= FEEDBACK_MAX_DEG for k in range(1, 7)] == [True] * 3 + \
        [False] * 3
    assert figures['mode'] == 'coiling' and first[4] > 0, (figures, first, total)
    # ... open loop beyond: not one correction from step 4 on.
    assert total == first[4], (first, total)
    # The coil follows the plan, the weaker magnets made up for by the corrections, carried
    # on past the feedback's end: open loop this rig fell 12, 11.5 and 10.5 deg short at
    # steps 3 to 5 (2026-12-03), coiling 5.5, 2.4 and 0.7.
    assert sorted(turns) == [1, 2, 3, 4, 5]
    for k, turn in turns.items():
        assert abs(turn - planned_deg[k - 1]) <= (10.0 if k < 3 else 7.0), (k, turns,
                                                                            planned_deg)
    # The release unwinds it: nothing coiled at the end.
    final = points_of(bag[contract.SIM_SHAPE.name][-1][1])
    assert abs(math.degrees(turning_rad(final))) < 10.0
