"""Thesis chapter 6: backbone and elastomer stiffness, and what the backbone does."""

import pathlib

import numpy as np
import pytest
from tentacle_model.chain import discretise
from tentacle_model.statics import solve, solve_planar
from tentacle_model.tentacle_spec import load_tentacle

VSR = pathlib.Path(__file__).resolve().parents[3] / 'config/tentacles/vsr_chapter6.yaml'


def test_chapter_6_stiffness_numbers():
    spec = load_tentacle(VSR)
    k_me = spec.segments[0].bend_stiffness_n_m2[0]
    k_bb = spec.backbone.stiffness_n_m2
    assert k_me == pytest.approx(7e-7, rel=0.05, abs=0)   # thesis: K_ME = 7e-7 N m^2 (6.67e-7)
    assert k_bb == pytest.approx(3e-4, rel=0.05, abs=0)   # thesis: K_BB = 3e-4 N m^2 (3.07e-4)
    # The thesis quotes a change factor of 765; its own inputs (eqs. 6.2-6.4: w = 2 mm,
    # h = 10 mm, r = 0.25 mm, n = 2) give (K_BB + K_ME) / K_ME = 461, which is what the
    # model uses. Either way the supported region is stiffer by over two orders.
    assert (k_bb + k_me) / k_me == pytest.approx(461, rel=0.01)


def test_backbone_region_does_not_bend():
    spec = load_tentacle(VSR)
    field = [0.0, 0.02, 0.0]
    free = solve_planar(discretise(spec, sublinks=2), field)
    supported = solve_planar(discretise(spec, sublinks=2, backbone_m=0.03), field)
    assert free.converged and supported.converged
    q_free = np.abs(np.diff(free.angles_rad, prepend=0.0))
    q_supported = np.abs(np.diff(supported.angles_rad, prepend=0.0))
    inside = discretise(spec, sublinks=2).s_start_m < 0.03 - 1e-9  # under the backbone (a link
    # starting where it ends is free)
    assert np.max(q_supported[inside]) < np.max(q_free[inside]) / 100
    assert np.max(q_supported[~inside]) > 0.05  # the distal part still bends


def coil_by_retraction(spec, field_t, backbone, dof=1, steps=24):
    """
    Withdraw the backbone while the field turns with it (thesis chapter 6); warm-started.

    With l of the strip released, its magnetisation (eq. 6.8, bending radius r) is held in a
    circle of radius r by a field at l / r: every released link then has its moment along
    the field. Return (tip heading in degrees, smallest stability on the way, all converged).
    """
    length, radius = spec.length_m, 0.0075
    state, lowest, converged = None, np.inf, True
    for released in np.linspace(0.0, length, steps + 1)[1:]:
        chain = discretise(spec, sublinks=2, backbone_m=length - released if backbone else 0.0)
        angle = released / radius
        eq = solve(chain, field_t * np.array([np.cos(angle), np.sin(angle), 0.0]),
                   initial=state, dof=dof)
        state, lowest, converged = eq.angles_rad, min(lowest, eq.stability), (
            converged and eq.converged)
    heading = state[-1] if dof == 1 else np.sum(state[:, 0])
    return np.degrees(heading), lowest, converged


@pytest.mark.parametrize('dof', [1, 3])
def test_withdrawing_the_backbone_with_a_turning_field_coils_the_strip(dof):
    spec = load_tentacle(VSR)
    heading, lowest, converged = coil_by_retraction(spec, 0.02, backbone=True, dof=dof)
    # Thesis Fig. 6.8: coiling to 360-400 degrees; eq. 6.8's full design is 458 degrees.
    assert converged and 400 < heading < 458 and lowest > 0
    # Without the backbone the same field history reaches the coil too, here, but only by
    # skirting a bifurcation: with the backbone the least stable step is some 1000 times
    # stiffer (3000 planar, 1000 in 3-DoF here).
    free_lowest = coil_by_retraction(spec, 0.02, backbone=False, dof=dof)[1]
    assert free_lowest < lowest / 300
