"""A recorded run split into its steps: the body when the next began, the deepest contact."""

from types import SimpleNamespace as Msg

import numpy as np
import pytest
from tentacle_common import contract
from tentacle_planner.paths import Path, shape_error
from tentacle_rig.run_report import step_spans, steps_of

NS = 1_000_000_000


def progress(step, inserted_m):
    return Msg(name=list(contract.PROGRESS_NAMES),
               position=[float(step), 2.0, inserted_m, float('nan'), float('nan')])


def shape(points):
    return Msg(poses=[Msg(pose=Msg(position=Msg(x=x, y=y, z=z))) for x, y, z in points])


def contact(count, depth_m):
    return Msg(name=['count', 'depth'], position=[float(count), depth_m])


def straight(length_m, bend_m=0.0):
    return [(0.0, 0.0, 0.0), (length_m, bend_m, 0.0)]


def test_each_step_is_the_body_as_the_next_began_and_its_deepest_contact():
    path = Path(np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]]))
    bag = {
        contract.PLAYER_PROGRESS.name: [
            (1 * NS, progress(1, 0.002)), (2 * NS, progress(1, 0.002)),
            (3 * NS, progress(2, 0.004)), (5 * NS, progress(2, 0.004))],
        contract.SIM_SHAPE.name: [(int(1.5 * NS), shape(straight(0.002, 0.0005))),
                                  (int(2.9 * NS), shape(straight(0.002, 0.0002))),
                                  (int(3.1 * NS), shape(straight(0.004, 0.0009))),
                                  (int(4.9 * NS), shape(straight(0.004, 0.0001)))],
        contract.SIM_CONTACT.name: [(int(1.2 * NS), contact(1, 0.0003)),
                                    (int(2.5 * NS), contact(1, 0.0001)),
                                    (int(4.0 * NS), contact(0, 0.0))]}
    assert step_spans(bag[contract.PLAYER_PROGRESS.name]) == [
        (1, 0.002, 1 * NS, 3 * NS), (2, 0.004, 3 * NS, 5 * NS)]
    first, second = steps_of(bag, path)
    # the last shape received before the next step began: the settled body
    assert first.shape_rms_m == pytest.approx(
        shape_error(np.array(straight(0.002, 0.0002)), path, 0.002)[0])
    assert first.contact_depth_m == pytest.approx(0.0003) and second.contact_depth_m == 0.0
    assert first.duration_s == pytest.approx(2.0) and second.duration_s is None
    assert second.shape_rms_m == pytest.approx(
        shape_error(np.array(straight(0.004, 0.0001)), path, 0.004)[0])
    assert set(first.row()) == {'insertion_m', 'shape_rms_m', 'tip_error_m', 'contact_depth_m',
                                'duration_s'}


def test_nothing_inserted_is_not_a_step():
    path = Path(np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]]))
    bag = {contract.PLAYER_PROGRESS.name: [(NS, progress(0, 0.0))],
           contract.SIM_SHAPE.name: [(NS // 2, shape([]))]}
    assert steps_of(bag, path) == []
