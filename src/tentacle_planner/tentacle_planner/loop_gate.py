"""
When the closed loop may act on a frame, and how fast and how late it acts: pure, no rclpy.

player_node asks a LoopGate of each tracked frame whether it may drive a correction: only a
frame taken after the last field change has settled and after the step's dwell began (frames
before show the stage moving or the old field), only until the loop has converged on the
step, and at most ``rate_hz`` times a second. Frame stamps and command times are ROS time
(the camera's clock), s; the rate and the figures are on a monotonic clock, s.
"""

from collections import deque
import math

import numpy as np


class LoopFigures:
    """The closed loop's rate and its latency from a frame's stamp to the field command."""

    def __init__(self):
        """Keep the recent past only."""
        self.latency_s = deque(maxlen=2000)
        self.intervals_s = deque(maxlen=2000)
        self.corrections, self._last = 0, None

    def evaluated(self, now, step, latency_s, corrected):
        """Record one frame evaluated at a step (monotonic s), with its latency, s."""
        if self._last is not None and self._last[1] == step:
            self.intervals_s.append(now - self._last[0])
        self._last = (now, step)
        if corrected:
            self.latency_s.append(latency_s)
            self.corrections += 1

    def rate_hz(self):
        """Return 1 / the median interval between two frames evaluated at one step, Hz."""
        return 1.0 / np.median(self.intervals_s) if self.intervals_s else math.nan

    def values(self):
        """Return the figures for /diagnostics: rate (Hz), latency median and p95 (ms)."""
        lat = np.percentile(self.latency_s, [50, 95]) * 1e3 if self.latency_s else [math.nan] * 2
        return {'loop_corrections': self.corrections, 'loop_rate_hz': f'{self.rate_hz():.1f}',
                'loop_latency_ms_median': f'{lat[0]:.1f}', 'loop_latency_ms_p95': f'{lat[1]:.1f}'}


class LoopGate:
    """Which frames may drive a correction; one per run."""

    def __init__(self):
        """Nothing commanded, nothing corrected yet."""
        self.frames_after_s = -math.inf    # ROS time: frames stamped before are stale
        self.last_correction_s = -math.inf  # monotonic
        self.converged = False
        self.figures = LoopFigures()

    def field_changed(self, stamp_s, settle_s):
        """Note a changed field command stamped at stamp_s; the coils settle in settle_s."""
        self.frames_after_s = stamp_s + settle_s

    def dwell_began(self, ros_now_s):
        """Note a step's dwell beginning at ros_now_s: earlier frames may show the stage moving."""
        self.frames_after_s = max(self.frames_after_s, ros_now_s)

    def new_step(self):
        """Note a new step: the loop works on it until it converges again."""
        self.converged = False

    def fresh(self, stamp_s, now_s, rate_hz):
        """Return whether a frame stamped stamp_s (ROS time) may drive a correction at now_s."""
        if self.converged or stamp_s < self.frames_after_s:
            return False
        return now_s - self.last_correction_s >= 1.0 / rate_hz

    def corrected(self, now_s, step, latency_s, converged):
        """
        Note a frame acted on at now_s (monotonic) at a step.

        :param latency_s: from the frame's stamp to the field command, s
        :param converged: the shape was within tolerance: no command was sent, the loop rests
        """
        self.last_correction_s = now_s
        self.converged = converged
        self.figures.evaluated(now_s, step, latency_s, not converged)
