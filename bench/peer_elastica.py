"""
The Cosserat-rod peer for bench/model_tradeoff.py: PyElastica with magneto-pyelastica.

Runs only in the bench-only environment (`make bench-env`; ../shared/NOTES.md section 8):
a dynamic rod relaxed with damping until its tip stops moving, timed in wall-clock seconds
so it can stand beside a static solve. Not imported by anything else in the project.
"""

import time

import elastica as ea
from magneto_pyelastica import ConstantMagneticField, MagneticForces
import numpy as np


class _Magnetic(MagneticForces):
    """magneto-pyelastica's torques, with the keyword PyElastica 1.0 passes (NOTES.md)."""

    def apply_torques(self, system, time=0.0):
        super().apply_torques(system, time)


class _Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
    pass


def relax_cantilever(n_elements, length_m, diameter_m, youngs_pa, density_kg_m3,
                     magnetisation_a_per_m, field_t, reference_tip_m, tolerance_m,
                     max_wall_s=30.0, damping=10.0, dt_per_length=0.01):
    """
    Relax an axially magnetised cantilever in a uniform field.

    The damping constant (1/s) is of the order of the rod's first bending frequency under
    the load (a few rad/s here): much less and the rod rings for seconds of simulated time.

    :return: dict with the tip (x, y) at the end, the wall time when the tip first came
        within tolerance_m of reference_tip_m (None if never) and the steps taken
    """
    simulator = _Simulator()
    rod = ea.CosseratRod.straight_rod(
        n_elements, np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
        length_m, diameter_m / 2, density_kg_m3, youngs_modulus=youngs_pa,
        shear_modulus=youngs_pa / 3.0)
    simulator.append(rod)
    simulator.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,),
                                   constrained_director_idx=(0,))
    dt = dt_per_length * length_m / n_elements
    field = ConstantMagneticField(np.asarray(field_t, dtype=float), ramp_interval=1e-3,
                                  start_time=0.0, end_time=1e9)
    simulator.add_forcing_to(rod).using(
        _Magnetic, external_magnetic_field=field,
        magnetization_density=float(magnetisation_a_per_m),
        magnetization_direction=np.array([1.0, 0.0, 0.0]), rod_volume=rod.volume,
        rod_director_collection=rod.director_collection)
    simulator.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=damping,
                                time_step=dt)
    simulator.finalize()
    stepper = ea.PositionVerlet()
    t, steps, reached, previous = 0.0, 0, None, None
    started = time.perf_counter()
    while time.perf_counter() - started < max_wall_s:
        for _ in range(500):
            t = stepper.step(simulator, t, dt)
        steps += 500
        tip = rod.position_collection[:2, -1].copy()
        if not np.all(np.isfinite(tip)):
            break
        # Settled within tolerance: inside it now, and moved less than a tenth of it since the
        # last check (a rod swinging through the target does not count).
        inside = np.linalg.norm(tip - reference_tip_m) <= tolerance_m
        still = previous is not None and np.linalg.norm(tip - previous) <= tolerance_m / 10
        previous = tip
        if inside and still:
            reached = time.perf_counter() - started
            break
    return {'tip_m': rod.position_collection[:2, -1].tolist(), 'wall_s_to_tolerance': reached,
            'steps': steps, 'simulated_s': t}
