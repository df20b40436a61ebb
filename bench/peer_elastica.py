"""
The Cosserat-rod peer for bench/model_tradeoff.py: PyElastica with magneto-pyelastica.

Runs only in the bench-only environment (`make bench-env`; ../shared/NOTES.md section 8):
a dynamic rod relaxed with damping until its tip stops moving, timed in wall-clock seconds
so it can stand beside a static solve. Not imported by anything else in the project.

Tuning, measured on the 90 degree cantilever (L = 20 mm, d = 2 mm, E = 100 kPa, 1400 kg/m^3,
Br = 0.107 T axial, 5 mT across; 2-core AMD EPYC shared with other work, so wall times are
noisy to about 30%):

- First bending mode under this load: half-period 48 ms in lightly damped runs, so
  w1 = 66 rad/s (37 rad/s unloaded; the field stiffens it) and critical damping 2 w1 = 132 1/s.
  Settling of the tip to 0.01% of L of its own rest point, in simulated ms (the same at 50
  and 100 elements), for uniform damping 10, 30, 60, 100, 120, 130, 160, 200 1/s:
  > 800, 594, 294, 191, 175, 182, 284, 383. DAMPING = 120 1/s, a little under critical.
- Time step: explicit; its limit 2 / w_max (build_cantilever) is within 3% of dl / c,
  c = sqrt(E / rho) = 8.5 m/s, from 50 elements up. Measured: 1.05 x the limit blows up at
  20 and 100 elements, 0.95 runs. COURANT = 0.85, i.e. dt = 0.1 s/m x dl at 100 elements,
  ten times the 0.01 s/m x dl used before; it ran stably from 10 to 200 elements and the
  rest shape does not depend on dt.
- Damping is needed for stability too: at 10 and 30 1/s the rod, after nearly coming to rest,
  starts to flutter (angular velocities grow at some 30 to 45 1/s, at dt 4e-6 and 4e-5 alike,
  with magneto-pyelastica's own torque routine as well) and flies apart by 0.9 and 2.2 s;
  45 1/s barely holds, 60 and 120 hold. So the earlier 10 1/s never settled at 100 elements.
- Discretisation: the rest tip is 1.43% of L off the elastica at 50 elements, 0.89% at 80,
  0.71% at 100 and 0.36% at 200 (error about 0.71% x 100 / n), so 50 elements never settle
  within 1% and 72 is the least that can.
- Settling, honestly: the tip inside the tolerance and moved no more than a tenth of it over
  the last STILL_S = 30 ms of simulated time (checked every 2 ms). A shorter look-back is
  fooled by the turning point of a swing: with 20 ms, 50 elements (rest 1.43% off) were
  declared settled within 1% at damping 10 and 100 1/s, and the earlier 500-step (2 ms)
  check so reported 50 elements within 1%. A rod stopped outside the tolerance ends the run.
"""

import collections
import time

import elastica as ea
from magneto_pyelastica import ConstantMagneticField, MagneticForces
import numba
import numpy as np


@numba.njit
def _add_magnetic_torques(torques, moments, directors, field):
    """
    Add m x (Q B) per element: the torque magneto-pyelastica computes, in one loop.

    Same arithmetic as MagneticForces.apply_torques (identical tips); that version builds
    temporaries and re-evaluates the ramp in Python on every step, about 40% of a step here.
    """
    for k in range(moments.shape[1]):
        b = (directors[0, 0, k] * field[0] + directors[0, 1, k] * field[1]
             + directors[0, 2, k] * field[2],
             directors[1, 0, k] * field[0] + directors[1, 1, k] * field[1]
             + directors[1, 2, k] * field[2],
             directors[2, 0, k] * field[0] + directors[2, 1, k] * field[1]
             + directors[2, 2, k] * field[2])
        torques[0, k] += moments[1, k] * b[2] - moments[2, k] * b[1]
        torques[1, k] += moments[2, k] * b[0] - moments[0, k] * b[2]
        torques[2, k] += moments[0, k] * b[1] - moments[1, k] * b[0]


class _Magnetic(MagneticForces):
    """magneto-pyelastica's torques as shipped, with the keyword PyElastica 1.0 passes."""

    def apply_torques(self, system, time=0.0):
        super().apply_torques(system, time)


class _MagneticCompiled(MagneticForces):
    """
    The same torques for a ConstantMagneticField, past its ramp in the compiled loop above.

    Not magneto-pyelastica's own code: the bench runs the peer both ways and reports both.
    """

    def apply_torques(self, system, time=0.0):
        field = self.external_magnetic_field
        if field.start_time + field.ramp_interval <= time <= field.end_time:
            value = field.magnetic_field_amplitude
        else:
            value = field.value(time=time)
        _add_magnetic_torques(system.external_torques, self.magnetization_collection,
                              system.director_collection, np.asarray(value, dtype=np.float64))


DAMPING = 120.0  # 1/s, uniform on velocities and angular velocities; module docstring
COURANT = 0.85  # of the explicit limit dl / sqrt(E / rho); module docstring
CHECK_S = 2e-3  # simulated s between looks at the tip
STILL_S = 3e-2  # simulated s the tip must have stayed put; a third of the first mode's period


class _Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
    pass


def build_cantilever(n_elements, length_m, diameter_m, youngs_pa, density_kg_m3,
                     magnetisation_a_per_m, field_t, damping, courant, compiled_torque=False):
    """
    Assemble the straight, clamped, axially magnetised rod with its field and damper.

    The time step is courant x 2 / w_max, the explicit limit, where w_max^2 = 4 E / (rho dl^2)
    (the stretch and bend waves across an element) + 16 a G / (rho d^2) (an element turning
    against its shear stiffness a G A, a = 27/28 as PyElastica sets it); the first term rules
    for elements shorter than the diameter.

    :param compiled_torque: the torque in one compiled loop instead of magneto-pyelastica's
    :return: (simulator, rod, time step in s)
    """
    shear_pa = youngs_pa / 3.0  # Poisson's ratio 0.5, PyElastica's default too
    simulator = _Simulator()
    rod = ea.CosseratRod.straight_rod(
        n_elements, np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
        length_m, diameter_m / 2, density_kg_m3, youngs_modulus=youngs_pa,
        shear_modulus=shear_pa)
    simulator.append(rod)
    simulator.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,),
                                   constrained_director_idx=(0,))
    w_max = np.sqrt((4 * youngs_pa / (length_m / n_elements) ** 2
                     + 16 * 27 / 28 * shear_pa / diameter_m ** 2) / density_kg_m3)
    dt = courant * 2 / w_max
    field = ConstantMagneticField(np.asarray(field_t, dtype=float), ramp_interval=1e-3,
                                  start_time=0.0, end_time=1e9)
    simulator.add_forcing_to(rod).using(
        _MagneticCompiled if compiled_torque else _Magnetic, external_magnetic_field=field,
        magnetization_density=float(magnetisation_a_per_m),
        magnetization_direction=np.array([1.0, 0.0, 0.0]), rod_volume=rod.volume,
        rod_director_collection=rod.director_collection)
    simulator.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=damping,
                                time_step=dt)
    simulator.finalize()
    return simulator, rod, dt


def relax_cantilever(n_elements, length_m, diameter_m, youngs_pa, density_kg_m3,
                     magnetisation_a_per_m, field_t, reference_tip_m, tolerance_m,
                     max_wall_s=30.0, damping=DAMPING, courant=COURANT,
                     compiled_torque=False):
    """
    Relax an axially magnetised cantilever in a uniform field; time it to the tolerance.

    Settled means the tip is within tolerance_m of reference_tip_m and has moved no more than
    a tenth of that over the last STILL_S of simulated time; the run ends there, when the rod
    has stopped outside the tolerance (moved less than a hundredth of it over STILL_S), when
    it diverges or after max_wall_s. Building the rod is not timed.

    :return: dict with the final tip (x, y), its error as a fraction of the length, the wall
        times when it settled and when it first came within the tolerance (None if never),
        the simulated time, steps, time step, damping and why the run ended
    """
    simulator, rod, dt = build_cantilever(n_elements, length_m, diameter_m, youngs_pa,
                                          density_kg_m3, magnetisation_a_per_m, field_t,
                                          damping, courant, compiled_torque)
    reference = np.asarray(reference_tip_m, dtype=float)[:2]
    per_check = max(1, round(CHECK_S / dt))
    history = collections.deque(maxlen=round(STILL_S / (per_check * dt)) + 1)
    stepper = ea.PositionVerlet()
    t, steps, first, settled, ended = 0.0, 0, None, None, 'wall time'
    started = time.perf_counter()
    while time.perf_counter() - started < max_wall_s:
        for _ in range(per_check):
            t = stepper.step(simulator, t, dt)
        steps += per_check
        tip = rod.position_collection[:2, -1].copy()
        if not np.all(np.isfinite(tip)):
            ended = 'diverged'
            break
        inside = np.linalg.norm(tip - reference) <= tolerance_m
        if inside and first is None:
            first = time.perf_counter() - started
        history.append(tip)
        if len(history) < history.maxlen:
            continue
        moved = max(np.linalg.norm(tip - past) for past in history)
        if inside and moved <= tolerance_m / 10:
            settled, ended = time.perf_counter() - started, 'settled'
            break
        if not inside and moved <= tolerance_m / 100:
            ended = 'stopped outside'
            break
    tip = rod.position_collection[:2, -1]
    return {'tip_m': tip.tolist(),
            'tip_error_of_L': float(np.linalg.norm(tip - reference) / length_m),
            'wall_s_to_tolerance': settled, 'wall_s_first_within': first,
            'simulated_s': float(t), 'steps': steps, 'dt_s': float(dt), 'damping_per_s': damping,
            'compiled_torque': compiled_torque, 'ended': ended}
