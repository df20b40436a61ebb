"""
The twisting instability (thesis chapters 4-5): obtuse magnets twist a soft rod.

A 40 mm, 6 mm rod with two magnets (thesis 4.5: 3.2 mm N52 at 18 and 38 mm): the proximal
one axial, at 90 degrees to the field, the tip one at 135 degrees. Unreinforced silicone is
isotropic (shear modulus E/3, so its twist pseudo-modulus with the polar moment is E/3):
as the field ramps up, the untwisted (planar) equilibrium loses stability and the rod twists
a long way and bends little. With a braid's 20:1 twist-to-bend stiffness (thesis Table 5.1)
the same rod stays untwisted and bends. The stability report flags the unstable state.
"""

import numpy as np
from tentacle_model import spatial
from tentacle_model.chain import discretise
from tentacle_model.statics import solve
from tentacle_model.tentacle_spec import parse_tentacle

MAGNET_BR_T = 1.45 * (1.6 / 3.0) ** 2  # an N52 magnet of 3.2 mm diameter in a 6 mm rod
UNREINFORCED = {'bend_1': 1e5, 'bend_2': 1e5, 'twist': 1e5 / 3}
BRAIDED = {'bend_1': 1e5, 'bend_2': 1e5, 'twist': 2e6}
FIELD_T = np.array([0.0, 0.02, 0.0])


def rod(moduli):
    def segment(length_m, direction=None):
        magnet = {'magnetisation': {'remanence_t': MAGNET_BR_T, 'direction': direction}}
        return {'length_m': length_m, 'section': {'diameter_m': 0.006},
                'youngs_modulus_pa': moduli, 'density_kg_m3': 1100.0,
                **(magnet if direction else {})}
    return parse_tentacle({'segments': [
        segment(0.0164), segment(0.0032, [1.0, 0.0, 0.0]), segment(0.0168),
        segment(0.0032, [-np.sqrt(0.5), -np.sqrt(0.5), 0.0]), segment(0.0004)]})


def ramp(chain):
    """Raise the field in steps, warm-starting each solve; return the last and the reasons."""
    state, reasons = None, []
    for scale in np.linspace(0.05, 1.0, 12):
        eq = solve(chain, scale * FIELD_T, dof=3, initial=state)
        assert eq.converged, eq.reason
        state = eq.angles_rad
        reasons.append(eq.reason)
    return eq, reasons


def twist_and_bend_deg(eq):
    bend = np.degrees(np.arccos(np.clip(eq.heading[0], -1.0, 1.0)))
    return abs(np.degrees(np.sum(eq.angles_rad[:, 2]))), bend


def untwisted_stability(chain):
    """Smallest 3-DoF Hessian eigenvalue at the planar (untwisted) equilibrium."""
    flat = solve(chain, FIELD_T, dof=1)
    q = np.column_stack([np.diff(flat.angles_rad, prepend=0.0), np.zeros((chain.size, 2))])
    state = spatial.evaluate(chain, q, FIELD_T)
    assert np.max(np.abs(state.gradient)) < 1e-9  # it is an equilibrium
    return np.linalg.eigvalsh(state.hessian)[0]


def test_unreinforced_rod_twists_and_braided_rod_bends():
    soft = discretise(rod(UNREINFORCED), sublinks=3)
    braided = discretise(rod(BRAIDED), sublinks=3)
    soft_eq, soft_reasons = ramp(soft)
    braided_eq, braided_reasons = ramp(braided)
    soft_twist, soft_bend = twist_and_bend_deg(soft_eq)
    braided_twist, braided_bend = twist_and_bend_deg(braided_eq)
    assert soft_twist > 90.0 and braided_twist < 1.0       # large twist against none
    assert braided_bend > soft_bend                         # the braid bends instead
    assert any('saddle' in r for r in soft_reasons)         # the ramp crossed an instability
    assert not any('saddle' in r for r in braided_reasons)
    assert untwisted_stability(soft) < 0 < untwisted_stability(braided)
