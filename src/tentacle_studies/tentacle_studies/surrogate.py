"""
A learned forward model: magnetisation angles -> what a study's table holds of each point.

Trained on a study's table (a babble: config/studies/ch2_babble.yaml), a network answers in
microseconds what the statics model solves in a fraction of a millisecond, as far as it
learnt it: bench/model_tradeoff.py sets its error and time beside the model's settings, the
fastest tier of that table. The angles enter as their cosines and sines (a turn is a turn).
"""

import numpy as np
from tentacle_studies import networks


class Surrogate:
    """Magnetisation angles (k,), rad -> outputs (m,): a fully connected network."""

    def __init__(self, layers=(32, 32), activation='tanh', seed=0, max_iterations=1500):
        """Set up an untrained network of hidden layer widths layers (networks.Network)."""
        self.network = networks.Network(layers, activation, seed, max_iterations)

    def fit(self, angles_rad, outputs):
        """Train on (N, k) angles, rad, and their (N, m) outputs; return self."""
        self.network.fit(_features(angles_rad), outputs)
        return self

    def __call__(self, angles_rad):
        """Return (N, m) outputs of (N, k) or (k,) angles, rad."""
        return self.network(_features(np.atleast_2d(angles_rad)))


def _features(angles_rad):
    return np.hstack([np.cos(angles_rad), np.sin(angles_rad)])
