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
from tentacle_sim.bringup import Rig, sim_table
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
        probe.target(LENGTH_M)
        assert wait_for(lambda: (s := probe.shape()) is not None
                        and arc_length_m(s) == pytest.approx(LENGTH_M, abs=1e-5), 30.0), (
            rig.process('sim_node').output())
        yield probe, devices, rig
    finally:
        probe.close()
        report = rig.stop()
    assert all(safe for _, _, _, safe in report), report


def settled(probe, since, check=lambda points: True, timeout_s=15.0):
    """
    Wait for a steady /sim/shape after since (its tip moved < 1 um since the one before)
    that passes check(points); return its points.
    """
    found = []

    def ok():
        shapes = [points_of(m) for m in probe.all('shape', since)[-2:]]
        if len(shapes) == 2 and len(shapes[0]) == len(shapes[1]) and np.linalg.norm(
                shapes[1][-1] - shapes[0][-1]) < 1e-6 and check(shapes[1]):
            found[:] = [shapes[1]]
            return True
        return False
    assert wait_for(ok, timeout_s), f'last shape: {probe.shape(since)}'
    return found[0]


def supply(devices, axis):
    return ask(devices, {'op': 'state'})[f'coil_{axis}']


def test_a_held_field_bends_the_body_as_the_elastica_says(rig):
    probe, devices, _ = rig
    probe.command_field([0.0, FIELD_T, 0.0])
    # The supply's output settles (slew, then the coil's L/R), then the body with it.
    assert wait_for(lambda: abs(supply(devices, 'y')['current_a'] - Y_AMPS) < 0.01, 10.0)
    since = time.monotonic() + 0.2
    points = settled(probe, since)
    assert np.linalg.norm(points[-1, :2] - TIP_M) < 0.02 * LENGTH_M, (points[-1], TIP_M)


def test_the_tracker_finds_the_rendered_tip_within_0_3_mm_of_the_truth(rig):
    probe, _, _ = rig
    since = time.monotonic()
    assert wait_for(lambda: len(probe.all('tip', since)) >= 5, 20.0)
    truth = {stamp_s(m): points_of(m)[-1] for m in probe.all('shape', since - 5.0)}
    pairs = [(m, truth[stamp_s(m)]) for m in probe.all('tip', since) if stamp_s(m) in truth]
    assert pairs, 'no /vision/tip with the stamp of a /sim/shape'
    for tip, true in pairs:   # the insertion point is the coil centre: workspace = coils xy
        seen = np.array([tip.pose.position.x, tip.pose.position.y])
        assert np.linalg.norm(seen - true[:2]) < 3e-4, (seen, true)
