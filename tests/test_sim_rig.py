"""
The simulated rig with the real drivers on its links, over DDS, as scripts/rig starts it.

sim_node, coils_node, inserter_node and tracker_node run as their own processes from the
bringup's process table (config/sim/*.yaml), on the validation cantilever (20 mm, planar)
with a ball beside where a field bends its tip. What the rig does is checked against
references the simulator does not share: the hard-magnetic elastica for the shape, the
geometry of the published points for contact depth, the emulated supplies' own state (read
over the control socket) for the currents. Tests run in order on one rig; each brings it to
the state it starts from.
"""

import time

import numpy as np
import pytest
from rig_support import ROOT, wait_for
from sim_probe import arc_length_m, points_of, SimProbe, stamp_s
from tentacle_model.elastica import cantilever_tip
from tentacle_rig.bringup import Rig, sim_table
from tentacle_sim.sim_devices import ask
import yaml

pytestmark = pytest.mark.ros

LENGTH_M, RADIUS_M = 0.020, 0.001
EI_N_M2 = 1.0e5 * np.pi * 0.002 ** 4 / 64
MA_A_M = 0.107 / (4e-7 * np.pi) * np.pi * 0.001 ** 2
FIELD_T = 0.005                             # along y: 90 deg to the rod
TIP_M = cantilever_tip(LENGTH_M, EI_N_M2, MA_A_M, FIELD_T, 90.0)   # (10.7, 15.3) mm
BALL_CENTRE_M = np.array([TIP_M[0], TIP_M[1] + 0.0015, 0.0])       # 1.5 mm past the tip
BALL_RADIUS_M = 0.001
Y_AMPS = FIELD_T / 1.07e-3                  # config/sim's y coil: 1.07 mT/A


def scene_file(folder):
    document = {
        'name': 'sim_cantilever', 'tentacle': str(ROOT / 'config/tentacles/cantilever.yaml'),
        'path': {'points_m': [[float(x), 0.0, 0.0] for x in np.linspace(0, LENGTH_M, 21)]},
        'insertion_steps_m': [LENGTH_M], 'model': {'dof': 1, 'sublinks': 32},
        'obstacles': [{'centre_m': BALL_CENTRE_M.tolist(), 'radius_m': BALL_RADIUS_M}]}
    path = folder / 'sim_cantilever.yaml'
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    """Return (probe, device folder, Rig): the simulated rig, the body inserted whole."""
    folder = tmp_path_factory.mktemp('sim_rig')
    devices = folder / 'devices'
    rig = Rig(sim_table(scene_file(folder), ROOT, devices), folder / 'logs', ROOT,
              say=lambda line: None)
    probe = SimProbe()
    try:
        assert probe.home(), rig.process('inserter_node').output()
        # Nothing inserted: the tracker sees the empty scene (the sheath, the phantom).
        assert probe.capture_background(), rig.process('tracker_node').output()
        assert probe.move_axis('inserter', LENGTH_M), rig.process('inserter_node').output()
        assert wait_for(lambda: (s := probe.shape()) is not None
                        and arc_length_m(s) == pytest.approx(LENGTH_M, abs=1e-5), 30.0), (
            rig.process('sim_node').output())
        yield probe, devices, rig
    finally:
        probe.close()
        report = rig.stop()
    assert all(safe for _, _, _, safe in report), report


def settled(probe, since, check=lambda points: True, timeout_s=15.0):
    """Wait for a steady /sim/shape after since that passes check(points); return it."""
    # Steady: its tip moved less than 1 um since the shape before.
    found = []

    def ok():
        shapes = [points_of(m) for m in probe.every('shape', since)[-2:]]
        if len(shapes) == 2 and len(shapes[0]) == len(shapes[1]) and np.linalg.norm(
                shapes[1][-1] - shapes[0][-1]) < 1e-6 and check(shapes[1]):
            found[:] = [shapes[1]]
            return True
        return False
    assert wait_for(ok, timeout_s), (
        f'{len(probe.every("shape", since))} shapes, the last two tips: '
        f'{[points_of(m)[-1] for m in probe.every("shape", since)[-2:]]}')
    return found[0]


def supply(devices, axis):
    return ask(devices, {'op': 'state'})[f'coil_{axis}']


def test_a_held_field_bends_the_body_as_the_elastica_says(rig):
    probe, devices, _ = rig
    assert probe.set_field([0.0, FIELD_T, 0.0], wait=False)
    # The supply's output settles (slew, then the coil's L/R), then the body with it.
    assert wait_for(lambda: abs(supply(devices, 'y')['current_a'] - Y_AMPS) < 0.01, 10.0)
    since = time.monotonic() + 0.2
    points = settled(probe, since)
    assert np.linalg.norm(points[-1, :2] - TIP_M) < 0.02 * LENGTH_M, (points[-1], TIP_M)


def test_the_tracker_finds_the_rendered_tip_within_0_3_mm_of_the_truth(rig):
    probe, _, _ = rig
    since = time.monotonic()

    def pairs():
        # A tip and the truth under the same stamp: a loaded probe may miss some of either
        # (the latest ten are kept for it), so pairs are gathered until there are enough.
        truth = {stamp_s(m): points_of(m)[-1] for m in probe.every('shape', since - 5.0)}
        return [(m, truth[stamp_s(m)]) for m in probe.every('tip', since)
                if stamp_s(m) in truth]
    assert wait_for(lambda: len(pairs()) >= 5, 30.0), (
        f"{len(pairs())} pairs of {len(probe.every('tip', since))} tips")
    for tip, true in pairs():   # the insertion point is the coil centre: workspace = coils xy
        seen = np.array([tip.pose.position.x, tip.pose.position.y])
        assert np.linalg.norm(seen - true[:2]) < 3e-4, (seen, true)


def test_contact_with_the_ball_is_reported_with_the_depth_the_shape_has(rig):
    probe, _, _ = rig
    since = time.monotonic()

    def pairs():   # a contact report and the shape under its stamp (see the tracker's test)
        shapes = {stamp_s(m): points_of(m) for m in probe.every('shape', since - 5.0)}
        return [(c, shapes[stamp_s(c)]) for c in probe.every('contact', since)
                if stamp_s(c) in shapes]
    assert wait_for(lambda: len(pairs()) >= 3, 30.0)
    checked = 0
    for contact, points in pairs():
        a, b = points[:-1], points[1:]   # each link a capsule of the rod's radius
        t = np.clip(np.einsum('ij,ij->i', BALL_CENTRE_M - a, b - a)
                    / np.einsum('ij,ij->i', b - a, b - a), 0.0, 1.0)
        gaps = np.linalg.norm(a + t[:, None] * (b - a) - BALL_CENTRE_M, axis=1) - (
            RADIUS_M + BALL_RADIUS_M)
        assert dict(zip(contact.name, contact.position)) == pytest.approx(
            {'count': np.count_nonzero(gaps < 0), 'depth': -gaps.min()}, abs=1e-9)
        assert contact.position[0] >= 1 and contact.header.frame_id == 'coils'
        checked += 1
    assert checked


def test_a_field_step_shows_in_the_shape_within_a_second(rig):
    probe, _, _ = rig
    before = settled(probe, time.monotonic())[-1]
    commanded = time.time()
    assert probe.set_field([0.0, FIELD_T / 2, 0.0], wait=False)
    since = time.monotonic()
    assert wait_for(lambda: any(np.linalg.norm(points_of(m)[-1] - before) > 1e-4
                                for m in probe.every('shape', since)), 10.0)
    first = next(m for m in probe.every('shape', since)
                 if np.linalg.norm(points_of(m)[-1] - before) > 1e-4)
    assert stamp_s(first) - commanded < 1.0   # the command, the supplies' slew, the solve


def test_a_stalled_stage_stops_the_insertion_where_it_stalled(rig):
    probe, devices, _ = rig
    assert probe.set_field([0.0, 0.0, 0.0], wait=False)
    probe.send_target('inserter', 0.005)
    settled(probe, time.monotonic(), lambda p: arc_length_m(p) == pytest.approx(0.005, abs=1e-5))
    ask(devices, {'op': 'fault', 'port': 'inserter', 'kind': 'stall', 'after_m': 0.006})
    probe.send_target('inserter', LENGTH_M)
    # The driver finds the move never ends, stops the axis and says so, as on the rig.
    node = rig[2].process('inserter_node')
    assert wait_for(lambda: 'did not finish' in node.output(), 30.0), node.output()
    points = settled(probe, time.monotonic())
    assert arc_length_m(points) == pytest.approx(0.011, abs=2e-5)   # where it stalled
    # Stopped unhomed, as a stall leaves an axis: zero where it stands, then in all the way.
    assert probe.home()
    probe.send_target('inserter', LENGTH_M - 0.011)
    settled(probe, time.monotonic(),
            lambda p: arc_length_m(p) == pytest.approx(LENGTH_M, abs=1e-5))


def test_estop_brings_the_supplies_to_zero_and_the_body_relaxes_straight(rig):
    probe, devices, _ = rig
    assert probe.set_field([0.0, FIELD_T, 0.0], wait=False)
    settled(probe, time.monotonic(), lambda p: p[-1, 1] > 0.01)
    probe.estop(True)
    probe.release_field()   # what a player does on an estop: commands stop
    try:
        # The currents read from the supplies themselves: the physics saw the real ones.
        assert wait_for(lambda: all(abs(s['current_a']) < 1e-3 and not s['output_on']
                                    for s in ask(devices, {'op': 'state'}).values()
                                    if 'current_a' in s), 10.0)
        points = settled(probe, time.monotonic(), lambda p: abs(p[-1, 1]) < 1e-6)
        assert points[-1, 0] == pytest.approx(LENGTH_M, abs=1e-6)   # straight along x
        assert probe.latest('contact').position[0] == 0
    finally:
        probe.estop(False)
    assert wait_for(lambda: probe.enable_coils(True), 10.0)


def test_a_supply_whose_line_is_lost_keeps_its_current_and_the_body_stays_bent(rig):
    probe, devices, _ = rig
    assert probe.set_field([0.0, FIELD_T, 0.0], wait=False)
    assert wait_for(lambda: abs(supply(devices, 'y')['current_a'] - Y_AMPS) < 0.01, 10.0)
    ask(devices, {'op': 'fault', 'port': 'coil_y', 'kind': 'disconnect', 'duration_s': 6.0})
    since = time.monotonic()
    # The driver reports the loss, as on the rig ...
    assert wait_for(lambda: (s := probe.status('coils: supply y', since)) is not None
                    and 'disconnected' in s[1], 10.0), probe.status('coils: supply y')
    # ... while the supply, out of its reach, goes on driving the coil: the body stays bent.
    assert supply(devices, 'y')['current_a'] == pytest.approx(Y_AMPS, abs=0.01)
    points = settled(probe, time.monotonic())
    assert np.linalg.norm(points[-1, :2] - TIP_M) < 0.02 * LENGTH_M
    probe.release_field()
    # Reconnected, the driver finds it holding current and drives it to zero.
    assert wait_for(lambda: abs(supply(devices, 'y')['current_a']) < 1e-3, 20.0)
    settled(probe, time.monotonic(), lambda p: abs(p[-1, 1]) < 1e-6)
    assert wait_for(lambda: probe.enable_coils(True), 10.0)


def test_markers_show_the_body_the_field_the_path_and_the_phantom(rig):
    probe, _, _ = rig
    assert probe.set_field([0.0, FIELD_T, 0.0], wait=False)
    settled(probe, time.monotonic(), lambda p: p[-1, 1] > 0.01)
    since = time.monotonic()
    assert wait_for(lambda: probe.latest('markers', since) is not None, 10.0)
    markers = {m.ns: m for m in probe.latest('markers', since).markers}
    assert set(markers) == {'path', 'obstacles', 'body', 'field'}
    assert all(m.header.frame_id == 'coils' for m in markers.values())
    body = np.array([[p.x, p.y, p.z] for p in markers['body'].points])
    assert len(body) == 33 and np.linalg.norm(body[-1, :2] - TIP_M) < 0.02 * LENGTH_M
    start, end = (np.array([p.x, p.y, p.z]) for p in markers['field'].points)
    assert end - start == pytest.approx(np.array([0.0, FIELD_T, 0.0]), abs=2e-5)   # 1 m/T
    ball = markers['obstacles']
    assert [ball.pose.position.x, ball.pose.position.y] == pytest.approx(BALL_CENTRE_M[:2])
    assert ball.scale.x == pytest.approx(2 * BALL_RADIUS_M)
    assert probe.set_field([0.0, 0.0, 0.0], wait=False)
