"""
Whole runs of the player on the simulated rig, over DDS, recorded, and faults in the middle.

One rig for the module (bringup.sim_table with player_node: sim_node, coils_node,
inserter_node, tracker_node, player_node) on the first 8 mm of the pancreatic duct with its
stated mismatch, driven through tentacle_rig's RigCommander as a lab script drives it. Each
test records its run with a recorder of its own (a rosbag2 directory read back with
rosbags) and confirms the actuators' state from the emulators themselves (the control
socket), never from what the drivers say. Tests run in order; each leaves the rig as it
found it (nothing inserted, zero field, no fault armed), but the last two: an estop or a
stall leaves the axis stopped where it was, to be homed again (the driver's rule), so the
stall is played from where the estop left the body.
"""

import time

import numpy as np
from plans import short_duct
import pytest
from rig_support import ROOT, wait_for
from tentacle_common import contract
from tentacle_planner import paths
from tentacle_rig.bringup import Rig, run_entries, sim_table
from tentacle_rig.commander_node import Outcome, RigCommander
from tentacle_rig.recording import read_bag
from tentacle_rig.run_report import steps_of
from tentacle_sim.sim_devices import ask
import yaml

pytestmark = pytest.mark.ros

STEPS_MM = (4, 8)            # key steps; played every 1 mm: 8 steps of about 0.5 s
MATRIX = np.diag([0.53e-3, 1.07e-3, 0.65e-3])   # config/sim/coils.yaml, T/A
RESULTS = {}                 # what one test measured and a later one compares with


@pytest.fixture(scope='module')
def schedule(tmp_path_factory):
    """Return (scene file, schedule file): the duct's first 8 mm, planned quickly."""
    return short_duct(tmp_path_factory.mktemp('navigation_plan'), STEPS_MM)


@pytest.fixture(scope='module')
def rig(schedule, tmp_path_factory):
    """Return (commander, device folder, Rig): up, homed, the empty scene captured."""
    scene_file, schedule_file = schedule
    folder = tmp_path_factory.mktemp('navigation_rig')
    planned = yaml.safe_load(schedule_file.read_text())['tentacle']
    tentacle = folder / 'made_to_plan.yaml'    # the rig's tentacle: the one made to the plan
    tentacle.write_text(yaml.safe_dump(planned))
    table = sim_table(scene_file, ROOT, folder / 'devices', schedule=schedule_file,
                      player={'tentacle': tentacle, 'settle_timeout_s': 1.0,
                              'feedback_timeout_s': 0.6})
    rig = Rig(table, folder / 'logs', ROOT, say=lambda line: None)
    commander = RigCommander('navigation_test')
    try:
        for step in (commander.wait_for_rig, commander.wait_for_player, commander.home,
                     commander.capture_background):
            result = step()
            assert result, (step.__name__, result, rig.process('player_node').output()[-3000:])
        yield commander, folder / 'devices', rig
    finally:
        commander.close()
        report = rig.stop()
    assert all(safe for _, _, _, safe in report), report


@pytest.fixture
def recording(rig, tmp_path):
    """Return a callable that stops this test's recorder and returns its bag, read."""
    commander, _, _ = rig
    bag = tmp_path / 'bag'
    recorder = Rig(run_entries(ROOT, None, record=bag), tmp_path / 'logs', ROOT,
                   say=lambda line: None)
    assert commander.wait_for_recorder([contract.PLAYER_PROGRESS, contract.SIM_SHAPE,
                                        contract.FIELD_CMD, contract.ESTOP])
    stopped = []

    def stop():
        if not stopped:
            stopped.append(recorder.stop())
            assert stopped[0][0][3], stopped   # 'recording closed', exit 0
        return read_bag(bag)
    yield stop
    stop()


def devices_state(devices):
    """Return (supplies {axis: state}, inserter stage state) as the emulators have them."""
    state = ask(devices, {'op': 'state'})
    return {a: state[f'coil_{a}'] for a in 'xyz'}, state['inserter']


def supplies_hold(devices, field_t, tolerance_a=0.05):
    """Return whether the supplies output the currents of a field (config/sim's matrix)."""
    supplies, _ = devices_state(devices)
    amps = np.linalg.solve(MATRIX, field_t)
    return all(abs(supplies[a]['current_a'] - amps[i]) <= tolerance_a
               for i, a in enumerate('xyz'))


def still_at(devices, position_m, tolerance_m=2e-5):
    """Return whether the inserter stage stands still at a position (its zero's frame)."""
    _, stage = devices_state(devices)
    return not stage['moving'] and abs(stage['position_m'] - position_m) <= tolerance_m


def progress_steps(bag):
    """Return the step indices /player/progress showed, in order, each once."""
    seen = []
    for _, msg in bag.get(contract.PLAYER_PROGRESS.name, []):
        index = int(msg.position[0])
        if not seen or seen[-1] != index:
            seen.append(index)
    return seen


def started_to_step(commander, step):
    """Start a run and wait until it plays a step (1-based)."""
    assert commander.player('start')
    since = time.monotonic()   # not the step an earlier run ended at
    assert wait_for(lambda: (p := commander.progress(since)) is not None and p.step >= step,
                    20.0)


def back_to_start(commander, devices):
    """Abort whatever runs, zero field, nothing inserted: where every test begins."""
    commander.player('abort')
    assert wait_for(lambda: supplies_hold(devices, np.zeros(3), 1e-3), 20.0)
    _, stage = devices_state(devices)
    if stage['position_m'] != 0.0:
        assert commander.move_axis('inserter', 0.0)
    assert still_at(devices, 0.0)


def test_an_open_loop_run_plays_every_step_and_records_it(rig, recording, schedule):
    commander, devices, _ = rig
    result = commander.play(mode='open_loop', timeout_s=60.0)
    assert result.outcome is Outcome.DONE, result
    # Read back from the devices: the stage at the last step, the last field held.
    last = yaml.safe_load(schedule[1].read_text())['steps'][-1]
    assert still_at(devices, last['insertion_m'])
    assert wait_for(lambda: supplies_hold(devices, np.array(last['field_t'])), 5.0)
    bag = recording()
    assert progress_steps(bag) == list(range(1, 9))
    path = paths.Path(np.array(yaml.safe_load(schedule[1].read_text())['path_m']))
    outcomes = steps_of(bag, path)
    assert [round(s.insertion_m * 1e3) for s in outcomes] == list(range(1, 9))
    RESULTS['open_loop_mm'] = np.mean([s.shape_rms_m for s in outcomes]) * 1e3
    assert RESULTS['open_loop_mm'] < 1.0       # the mismatch shows, within a millimetre
    assert len(bag[contract.FIELD_CMD.name]) >= 8 and contract.SIM_SHAPE.name in bag


def test_a_retraction_plays_the_steps_backwards_to_nothing_inserted(rig, recording):
    commander, devices, _ = rig
    result = commander.play(retract=True, timeout_s=60.0)
    assert result.outcome is Outcome.DONE, result
    assert still_at(devices, 0.0)
    assert wait_for(lambda: supplies_hold(devices, np.zeros(3), 1e-3), 5.0)
    assert progress_steps(recording()) == [8, 7, 6, 5, 4, 3, 2, 1, 0]


def test_the_closed_loop_corrects_the_field_and_cuts_the_shape_error(rig, recording,
                                                                     schedule):
    commander, devices, _ = rig
    try:
        result = commander.play(mode='closed_loop', timeout_s=60.0)
        figures = commander.status('player_node: run').values
        bag = recording()
    finally:   # the next test starts where this one should end, whatever happened here
        back_to_start(commander, devices)
        commander.set_player(mode='open_loop')
    assert result.outcome is Outcome.DONE, result
    path = paths.Path(np.array(yaml.safe_load(schedule[1].read_text())['path_m']))
    closed_mm = np.mean([s.shape_rms_m for s in steps_of(bag, path)]) * 1e3
    assert int(figures['loop_corrections']) > 0
    # closed / open: 0.69-0.71 on an idle machine, 0.81 in a loaded CI run (the loop's
    # frames come later there); open loop alone it is 1
    assert closed_mm < 0.9 * RESULTS['open_loop_mm'], (closed_mm, RESULTS)


def test_a_paused_run_holds_the_field_and_the_stage_then_resumes(rig, recording):
    commander, devices, _ = rig
    started_to_step(commander, 3)
    assert commander.player('pause')
    held = commander.latest('field')
    time.sleep(0.5)   # past a move in flight: a pause lets it finish
    _, stage = devices_state(devices)
    assert not stage['moving']
    where = stage['position_m']
    time.sleep(1.5)   # longer than coils_node's 1 s watchdog: the player keeps the field fed
    assert still_at(devices, where)
    field = np.array([held.vector.x, held.vector.y, held.vector.z])
    assert supplies_hold(devices, field)
    assert commander.player('resume')
    result = commander.wait_for_run(30.0)
    assert result.outcome is Outcome.DONE, result
    steps = progress_steps(recording())
    steps = steps[steps.index(1):]   # before: the last run's end, still said
    assert steps == list(range(1, 9))   # in order, none repeated or skipped
    back_to_start(commander, devices)


def test_a_supply_lost_mid_run_pauses_it_and_an_abort_zeroes_it_once_back(rig, recording):
    commander, devices, _ = rig
    started_to_step(commander, 3)
    ask(devices, {'op': 'fault', 'port': 'coil_y', 'kind': 'disconnect', 'duration_s': 3.0})
    result = commander.wait_for_run(10.0)
    assert result.outcome is Outcome.PAUSED, result
    assert 'supply y' in result.message or contract.FIELD.name in result.message, result
    # Paused, a move in flight finishes: aborted at rest (as its driver reports it), the
    # axis stays homed.
    assert wait_for(lambda: not devices_state(devices)[1]['moving']
                    and commander.latest('state:inserter').velocity[0] == 0.0, 5.0)
    assert commander.player('abort')
    # Out of the driver's reach the supply holds its current; once back, the driver zeroes it.
    assert wait_for(lambda: supplies_hold(devices, np.zeros(3), 1e-3), 20.0)
    assert progress_steps(recording())[-1] >= 3
    assert wait_for(lambda: commander.enable_coils(True), 10.0)
    back_to_start(commander, devices)


def test_a_schedule_for_another_tentacle_or_over_the_limits_is_refused(rig, schedule, tmp_path):
    commander, devices, _ = rig
    document = yaml.safe_load(schedule[1].read_text())
    # The rig's tentacle with its tip magnetised 90 deg off the one the plan was made for.
    turned = yaml.safe_load((ROOT / 'config/tentacles/braided_chapter5.yaml').read_text())
    turned['segments'][-1]['magnetisation']['direction'] = [0.0, 1.0, 0.0]
    other = dict(document, tentacle=turned)
    strong = dict(document, steps=[dict(s, field_t=[0.0, 0.025, 0.0]) for s in
                                   document['steps']])
    unknown = dict(document, format='tentacle-schedule/99')
    expected = {'other': 'planned for another tentacle than', 'strong': '22 mT per axis',
                'unknown': 'is not a format this reader knows'}
    for name, doc in (('other', other), ('strong', strong), ('unknown', unknown)):
        path = tmp_path / f'{name}.yaml'
        path.write_text(yaml.safe_dump(doc))
        assert commander.set_player(schedule=str(path))
        result = commander.player('start')
        assert result.outcome is Outcome.REFUSED and expected[name] in result.message, result
    assert still_at(devices, 0.0) and supplies_hold(devices, np.zeros(3), 1e-3)
    assert commander.set_player(schedule=str(schedule[1]))


def test_another_publisher_of_the_field_command_pauses_the_run(rig):
    commander, devices, _ = rig
    started_to_step(commander, 2)
    with RigCommander('intruder') as intruder:
        intruder.set_field(np.zeros(3), timeout_s=1.0)
        result = commander.wait_for_run(10.0)
    assert result.outcome is Outcome.PAUSED, result
    assert f'another node publishes {contract.FIELD_CMD.name}: ' in result.message, result
    back_to_start(commander, devices)


def test_an_estop_mid_run_pauses_it_and_the_supplies_go_to_zero(rig, recording):
    commander, devices, _ = rig
    started_to_step(commander, 3)
    assert commander.estop(True)
    try:
        result = commander.wait_for_run(10.0)
        assert result.outcome is Outcome.PAUSED and 'estop' in result.message, result
        assert wait_for(lambda: all(abs(s['current_a']) < 1e-3 and not s['output_on']
                                    for s in devices_state(devices)[0].values()), 10.0)
        assert wait_for(lambda: not devices_state(devices)[1]['moving'], 5.0)
        refused = commander.player('resume')
        assert refused.outcome is Outcome.REFUSED and 'estop' in refused.message
    finally:
        commander.estop(False)
    bag = recording()
    assert True in [m.data for _, m in bag[contract.ESTOP.name]]   # up to the fault
    assert progress_steps(bag)[-1] >= 3
    assert commander.enable_coils(True)
    assert commander.player('abort')
    assert wait_for(lambda: supplies_hold(devices, np.zeros(3), 1e-3), 20.0)
    # The estop stopped the axis mid-move: the driver wants it homed again before it moves.
    assert commander.home()


def test_a_stage_stall_mid_run_pauses_it_saying_where_the_stage_is(rig, recording):
    commander, devices, _ = rig
    started_to_step(commander, 2)
    ask(devices, {'op': 'fault', 'port': 'inserter', 'kind': 'stall', 'after_m': 0.0015})
    result = commander.wait_for_run(15.0)
    assert result.outcome is Outcome.PAUSED, result
    assert 'not there after' in result.message and 'the inserter at' in result.message
    _, stage = devices_state(devices)
    assert not stage['moving']
    assert commander.player('abort')
    assert wait_for(lambda: supplies_hold(devices, np.zeros(3), 1e-3), 10.0)
    assert progress_steps(recording())[-1] >= 2
    # The driver stopped the stalled axis and left it to be homed again (the last test)
