"""
What a recorded run achieved, step by step: measured on the truth, from the recording alone.

``steps_of(bag, path)`` splits a run's recording (tentacle_rig.recording.read_bag) into its
steps by /player/progress (a step begins when the index first shows) and takes, for each, the
body as it stood when the next step began: the last /sim/shape received before then (the
simulated rig's ground truth, frame coils). Its shape error is DESIGN.md's
(paths.shape_error against the desired path at the step's inserted length); its contact the
deepest /sim/contact during the step. The closed loop's rate and latency come from the
player's last /diagnostics status. Pure: no rclpy.
"""

from dataclasses import asdict, dataclass
import math

import numpy as np
from tentacle_common import contract
from tentacle_planner import paths


@dataclass(frozen=True)
class StepOutcome:
    """One played step, as the truth saw it when the next began. Metres, seconds."""

    index: int
    insertion_m: float
    shape_rms_m: float
    tip_error_m: float
    contact_depth_m: float
    duration_s: float | None   # None for the last step: it lasts until the recording ends
    points_m: np.ndarray    # (k, 3) the body, frame coils

    def row(self):
        """Return the step as a report.json row: DESIGN.md's keys and the step's time."""
        out = asdict(self)
        del out['points_m'], out['index']
        return out


def points_of(path_msg):
    """Return (N, 3) the positions of a nav_msgs/Path, m."""
    return np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                     for p in path_msg.poses]).reshape(-1, 3)


def step_spans(progress):
    """Return [(index, insertion m, begin ns, end ns)] of /player/progress [(ns, msg)]."""
    spans = []
    for time_ns, msg in progress:
        values = dict(zip(msg.name, msg.position))
        index = int(values['step'])
        if not spans or spans[-1][0] != index:
            spans.append([index, float(values['insertion']), time_ns, time_ns])
        spans[-1][3] = time_ns
    for this, after in zip(spans, spans[1:]):
        this[3] = after[2]
    return [tuple(s) for s in spans]


def steps_of(bag, path):
    """
    Return the StepOutcomes of a recorded run (steps with something inserted).

    :param bag: {topic: [(receive ns, message)]} (recording.read_bag)
    :param path: the desired path (paths.Path), frame coils
    """
    shapes = bag.get(contract.SIM_SHAPE.name, [])
    contacts = bag.get(contract.SIM_CONTACT.name, [])
    shape_times = np.array([t for t, _ in shapes], dtype=np.int64)
    out = []
    spans = step_spans(bag.get(contract.PLAYER_PROGRESS.name, []))
    for k, (index, inserted, begin, end) in enumerate(spans):
        last = int(np.searchsorted(shape_times, end, side='left')) - 1
        if inserted <= 0 or last < 0:
            continue
        body = points_of(shapes[last][1])
        rms, tip = paths.shape_error(body, path, min(inserted, path.length_m))
        depth = max((dict(zip(m.name, m.position)).get('depth', 0.0)
                     for t, m in contacts if begin <= t < end), default=0.0)
        duration = (end - begin) * 1e-9 if k + 1 < len(spans) else None
        out.append(StepOutcome(index, inserted, rms, tip, float(depth), duration, body))
    return out


def loop_figures(bag):
    """Return the player's last /diagnostics values (mode, loop rate and latency), or {}."""
    for _, array in reversed(bag.get(contract.DIAGNOSTICS.name, [])):
        for status in array.status:
            if status.name == 'player_node: run':
                return {v.key: v.value for v in status.values}
    return {}


def mean_shape_rms(steps):
    """Return the mean of the steps' shape RMS, m (NaN without steps)."""
    return float(np.mean([s.shape_rms_m for s in steps])) if steps else math.nan
