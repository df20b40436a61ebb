"""Refusing a schedule: the coils' limits and the tentacle it was planned for."""

import pathlib

import numpy as np
from tentacle_model.tentacle_spec import load_tentacle
from tentacle_planner.mismatch import perturbed
from tentacle_planner.schedule_check import CoilLimits, field_refusals, tentacle_refusals

ROOT = pathlib.Path(__file__).resolve().parents[3]
LAB = CoilLimits(max_field_t=0.022, max_total_field_t=0.030, max_field_change_t=0.015)


def test_fields_within_every_limit_are_not_refused():
    fields = [[0.0, 0.005, 0.0], [0.010, 0.015, 0.0], [0.020, 0.020, 0.0], [0.010, 0.010, 0.0]]
    assert field_refusals(fields, LAB) == []
    assert field_refusals(fields, CoilLimits()) == []   # no limits: nothing refused


def test_each_limit_is_named_with_the_step_and_the_numbers():
    assert field_refusals([[0.0, 0.023, 0.0]], LAB, from_zero=False) == [
        "step 1: a field component of 23.00 mT is over the coils' 22 mT per axis"]
    assert field_refusals([[0.0, 0.010, 0.010], [0.0, 0.020, 0.020]], LAB, from_zero=False) == []
    total = field_refusals([[0.0, 0.010, 0.0], [0.0, 0.022, 0.022]], LAB)
    assert "step 2: |B| 31.11 mT is over the coils' 30 mT in total" in total
    change = field_refusals([[0.0, 0.010, 0.0], [0.0, -0.010, 0.0]], LAB)
    assert change == ["step 1 to step 2: 20.00 mT of change on one axis is over the coils' "
                      '15 mT per step']


def test_the_run_starts_and_ends_at_zero_field():
    # 16 mT at the first step is a 16 mT change from the zero the run starts at
    assert field_refusals([[0.016, 0.0, 0.0], [0.010, 0.0, 0.0]], LAB) == [
        "zero field to step 1: 16.00 mT of change on one axis is over the coils' 15 mT per "
        'step']
    assert field_refusals([[0.010, 0.0, 0.0], [0.016, 0.0, 0.0]], LAB)[0].startswith(
        'step 2 to zero field')
    assert field_refusals([[0.016, 0.0, 0.0], [0.010, 0.0, 0.0]], LAB, from_zero=False) == []


def test_a_field_that_is_not_finite_is_refused():
    assert field_refusals([[0.0, np.nan, 0.0]], LAB) == ['step 1: the field is not finite']


def test_the_same_tentacle_passes_and_another_is_named():
    spec = load_tentacle(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml')
    assert tentacle_refusals(spec, spec) == []
    assert tentacle_refusals(perturbed(spec, stiffness=1.005), spec) == []   # within 1 %
    softer = tentacle_refusals(perturbed(spec, stiffness=0.9), spec)
    assert softer[0] == 'segment 1: the moduli differs' and len(softer) == 5
    turned = spec.segments[2].magnetisation_a_per_m
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    other = load_tentacle(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml')
    other.segments[2].magnetisation_a_per_m[:] = rotation @ turned
    assert tentacle_refusals(other, spec) == [
        "segment 3: the magnetisation is 90 deg from the rig's tentacle"]
    cantilever = load_tentacle(ROOT / 'config' / 'tentacles' / 'cantilever.yaml')
    assert tentacle_refusals(spec, cantilever) == [
        f"5 segments planned, the rig's tentacle {cantilever.name!r} has "
        f'{len(cantilever.segments)}']


def test_the_tightest_of_two_limits():
    assert CoilLimits(0.022, None, 0.015).tightest(CoilLimits(0.020, 0.030, None)) == \
        CoilLimits(0.020, 0.030, 0.015)
