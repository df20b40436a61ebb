"""
Loads on the links in the world frame, for every joint model: energy and its derivatives.

A link load is an energy E(m, c) of every link's world moment m_i (A m^2) and centre c_i (m),
given with dE/dm_i (T), dE/dc_i (N) and, when asked, its Hessian in x = (m_1 .. m_n,
c_1 .. c_n): a dipoles.Interaction. Each joint model projects the sum of a chain's loads into
its own joint angles in one place (planar.project_loads, spatial.evaluate), so a new load, wall
contact say, is written once, here, in world coordinates, and both models have it. The
uniform field, gravity and elasticity stay in the compiled passes, where they are cheaper.
"""

import numpy as np
from tentacle_model import dipoles


class DipoleLoad:
    """Magnet-to-magnet interaction between the links of different segments (dipoles.py)."""

    def __init__(self, chain):
        """Fix the interacting pairs of a chain and how close each may come."""
        self.pairs = chain.interacting_pairs()
        self.contact_m = chain.contact_distances(self.pairs)

    def __call__(self, moments_a_m2, centres_m, hessian):
        """Return the Interaction at world moments (n, 3) and centres (n, 3)."""
        return dipoles.pair_interaction(moments_a_m2, centres_m, *self.pairs, hessian,
                                        self.contact_m)


def of_chain(chain, dipoles=False):
    """Return the loads a chain carries in a model: () or (DipoleLoad,)."""
    return (DipoleLoad(chain),) if dipoles and chain.interacting_pair_count() else ()


def total(loads, moments_a_m2, centres_m, hessian=True):
    """
    Return the Interaction of every load summed, or None for no loads.

    :param loads: callables (moments, centres, hessian) -> dipoles.Interaction
    """
    parts = [load(moments_a_m2, centres_m, hessian) for load in loads]
    if len(parts) < 2:
        return parts[0] if parts else None
    return dipoles.Interaction(
        float(sum(p.energy_j for p in parts)), np.sum([p.grad_moments for p in parts], axis=0),
        np.sum([p.grad_centres for p in parts], axis=0),
        np.sum([p.hessian for p in parts], axis=0) if hessian else None)
