"""The simulator's own figures: frame rate, physics and render time (for its diagnostics)."""

import collections
import time

import numpy as np

KEPT = 300  # the last frames the figures are over (10 s at 30 Hz)


class RateMeter:
    """Frame times, solve and render durations of the last KEPT frames."""

    def __init__(self, clock=time.monotonic):
        """Start empty; clock gives seconds."""
        self._clock = clock
        self._frames = collections.deque(maxlen=KEPT)   # (t, solve s, render s)

    def tick(self, solve_s, render_s):
        """Count a frame now, with its solve and render durations, s."""
        self._frames.append((self._clock(), solve_s, render_s))

    def figures(self):
        """Return {'rate_hz', 'physics_ms_median', 'physics_ms_p95', 'render_ms_median'}."""
        if len(self._frames) < 2:
            return {'rate_hz': 0.0}
        t, solve, render = (np.array(column) for column in zip(*self._frames))
        return {'rate_hz': round((len(t) - 1) / max(t[-1] - t[0], 1e-9), 2),
                'physics_ms_median': round(1e3 * float(np.median(solve)), 2),
                'physics_ms_p95': round(1e3 * float(np.percentile(solve, 95)), 2),
                'render_ms_median': round(1e3 * float(np.median(render)), 2)}
