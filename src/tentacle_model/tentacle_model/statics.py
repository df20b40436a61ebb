"""
Forward statics: the equilibrium of a chain in a uniform field, by minimising its energy.

Newton's method on the analytic gradient and Hessian, with a Levenberg shift where the
Hessian is not positive definite, a step cap and an Armijo line search on the energy. The
start is the caller's previous state (warm start): quasi-static history decides which branch
the rod is on. A converged point whose Hessian has a negative eigenvalue is a saddle, not a
minimum: the solver pushes off along that eigenvector and minimises again (a bounded number
of times). Every result says whether it converged and why, with the iteration count, the
residual and the stability (the smallest Hessian eigenvalue: negative or near zero means
unstable or at a bifurcation). It never returns NaN silently.

Two joint models share the minimiser: planar 1-DoF joints (planar.py, O(n) per step with
a tridiagonal Hessian) and 3-DoF bend-bend-twist joints (spatial.py, dense Hessian); each
has a linearised (small-angle) form, and either can add the magnets' interaction
(dipoles.py), which couples every link with every other (a dense Hessian). The 3-DoF model
without the interaction runs the same minimiser compiled (spatial_newton.py): a 5-link solve
in tens of microseconds rather than 0.3 ms of Python calls.

A problem too large to answer within the time limit is refused before any work
(check_size: MAX_LINKS per joint model, MAX_ESTIMATED_BYTES of dense arrays), and the time
limit is checked before every Newton step and line-search trial (the compiled minimiser's:
before every call of a few steps, one from 174 angles up).
"""

import contextlib
from dataclasses import dataclass
import time

import numpy as np
from scipy.linalg import eigh, eigh_tridiagonal, LinAlgError, solveh_banded
from scipy.linalg.lapack import dpotrf as potrf, dpotrs as potrs, dptsv as ptsv
from tentacle_model import link_loads, planar, planar_newton, spatial, spatial_newton
from tentacle_model.chain import Chain, MAX_CHAIN_LINKS, ProblemTooLarge
from tentacle_model.dipoles import Contact
from threadpoolctl import ThreadpoolController

MAX_STEP_RAD = 0.5       # largest change of any angle in one Newton step
MAX_SADDLE_ESCAPES = 5
SMALL_ANGLE_LIMIT_RAD = 0.3
"""
The largest link angle from the insertion direction the small-angle model is answered for.

At 0.3 rad sin x = x within 1.5 % and cos x = 1 within 4.5 %; the linearised kinematics
lengthen such a link by 4.4 % (sqrt(1 + x^2)). Past it small_angle_violation says so.
"""
ESCAPE_STEP_RAD = 0.05
COMPILED_STEP_WORK = 30_000
"""The compiled Newton's steps a call, times the problem's size squared: the deadline is
checked between calls (16 steps a call for a 15-angle chain, one from 174 angles up)."""
# Dense Hessians of these sizes are factorised on one BLAS thread: measured here, with the
# other core busy a 150 x 150 Cholesky took 0.12 ms on one thread and 0.8 ms on two (the
# hand-off costs more than the arithmetic); past the upper size the threads pay for
# themselves, and below the lower one OpenBLAS uses one thread anyway (and switching costs
# 35 us, a tenth of a small solve).
SINGLE_THREAD_SIZES = (32, 600)
MAX_LINKS = {1: MAX_CHAIN_LINKS, 3: 250}
"""
The most links a solve accepts, per joint model (dof): larger problems are refused at once.

Planar: O(n) per Newton step (chain.MAX_CHAIN_LINKS). 3-DoF: a dense (3n, 3n) Hessian,
factorised in every Newton step, and its smallest eigenpair (LAPACK's dsyevr, which first
reduces the whole matrix to tridiagonal form) at the end and wherever the Hessian is
indefinite. Measured here (2 cores): at 250 links a Cholesky takes 11 to 15 ms, the
eigenpair 30 to 45 ms and a cold solve 0.1 to 1.6 s; at 3000 links 3 s, 35 to 44 s and 1
to 2 minutes.
"""
MAX_ESTIMATED_BYTES = 40 * 2 ** 20
"""
The most memory (estimate_memory_bytes) a solve may need; larger problems are refused.

Set by time, not by RAM: it bounds the dense problems, whose work grows as the 1.5th power
of their memory. With magnet-to-magnet interaction it is the binding limit: 215 to 245
planar or 145 to 170 3-DoF links (fewer with more segments, hence more pairs); cold solves
there take 0.1 to 2 s here, 4.7 s at worst (24 magnets folding onto each other until they
touch, 27 Newton steps). bench/model_tradeoff.py's largest, the braided tentacle at 160
3-DoF links with dipoles, needs 38.7 MiB. The 3-DoF model without dipoles reaches
MAX_LINKS first (26 MiB).
"""
_BYTES_PER_LINK = 256  # the chain's arrays (11 doubles a link) and the solver's vectors
_DENSE_COPIES = 6  # live copies of a dense Hessian: two evaluations, factor, eigh, shifted
# The interaction's (6n, 6n) Hessian and four (6n, N) arrays, and 720 bytes a pair: what the
# numpy projection and pair loop of before kept. The compiled ones keep one (N, 6n) array and
# 8 bytes a pair; the figures stay so that the limit, set by time, stays where it was measured.
_DIPOLE_BYTES_PER_PAIR = 720
_DIPOLE_COPIES = 5
_BLAS = []  # the ThreadpoolController, made on first use (it inspects the loaded libraries)
_COMPILED = []  # [True] once the compiled passes are ready (solve keeps them off its clock)


@dataclass(frozen=True)
class Equilibrium:
    """A solve's result; arrays over links base first, SI units."""

    angles_rad: np.ndarray    # planar: (n,) absolute link angles; 3-DoF: (n, 3) joint angles
    points_m: np.ndarray      # (n + 1, 3) joints and tip, world frame
    converged: bool
    reason: str
    iterations: int
    residual: float           # max |dU/dq| over the largest torque in the balance
    stability: float          # smallest Hessian eigenvalue, N m / rad^2 (nan if unknown)
    energy_j: float

    @property
    def tip_m(self):
        """Return the tip position (3,), m."""
        return self.points_m[-1]

    @property
    def heading(self):
        """Return the tip's unit direction (3,) in the world frame."""
        if len(self.points_m) < 2:
            return np.array([1.0, 0.0, 0.0])
        step = self.points_m[-1] - self.points_m[-2]
        return step / np.linalg.norm(step)


class _Planar:
    """Planar chain: x = absolute link angles (n,); linear: small-angle model."""

    def __init__(self, chain, field_t, gravity_m_s2, linear=False, loads=()):
        self.chain = chain
        self.linear = linear
        # World-frame link loads (interacting dipoles) couple every link with every other:
        # a dense Hessian.
        self.loads = tuple(loads)
        self.k = chain.stiffness_n_m[:, 0].copy()
        self.a, self.b = planar.loads(chain, field_t, gravity_m_s2)
        self.load_scale = np.max(np.abs(self.a) + np.abs(self.b))
        self.k_floor = max(1e-9 * np.max(self.k), 1e-300)
        self.size = chain.size
        self._key, self._value = None, None

    def evaluate(self, x):
        """Return (energy, gradient, banded Hessian) at x, remembering the last one."""
        # The minimiser never changes an array in place: the same object is the same point.
        # A line search's trial is evaluated in full: it is usually the next iterate.
        if x is not self._key:
            u, g, banded = planar.evaluate(x, self.k, self.a, self.b, self.linear, True)
            if self.loads:
                du, dg, _ = planar.project_loads(self.chain, x, self.loads, False)
                u, g = u + du, g + dg
            self._key, self._value = x, (u, g, banded)
        return self._value

    def energy(self, x):
        return self.evaluate(x)[0]

    def gradient(self, x):
        return self.evaluate(x)[1]

    def dense_hessian(self, x):
        banded = self.evaluate(x)[2]
        h = np.diag(banded[1]) + np.diag(banded[0, 1:], 1) + np.diag(banded[0, 1:], -1)
        return h + planar.project_loads(self.chain, x, self.loads, True)[2]

    def torque_scale(self, x):
        return max(self.load_scale, np.abs(self.k * planar.joint_angles(x)).max(),
                   self.k_floor)

    def newton_step(self, x, g):
        if self.loads:
            return _dense_newton_step(self.dense_hessian(x), g)
        banded = self.evaluate(x)[2]
        diagonal = banded[1]
        if self.size == 1:  # LAPACK's tridiagonal solvers need two
            scale = max(abs(diagonal[0]), 1e-300)
            return -g / (diagonal[0] if diagonal[0] > 0 else abs(diagonal[0]) + 1e-8 * scale)
        step, info = ptsv(diagonal, banded[0, 1:], -g)[2:]  # positive definite: plain Newton
        if info == 0:
            return step
        # Indefinite: shift just past the most negative eigenvalue (a compiled bisection),
        # rather than searching for a shift that factorises (ten tries on average).
        lowest = float(planar.smallest_eigenvalue(diagonal, banded[0, 1:]))
        shift = -lowest + 1e-6 * max(np.max(np.abs(diagonal)), 1e-300)
        step, info = ptsv(diagonal + shift, banded[0, 1:], -g)[2:]
        if info == 0:
            return step
        return _shifted_solve(lambda shift: solveh_banded(
            banded + np.array([[0.0], [shift]]), g, check_finite=False), diagonal, g)

    def smallest_eigen(self, x):
        if self.loads:
            return _dense_smallest_eigen(self.dense_hessian(x))
        banded = self.evaluate(x)[2]
        diagonal, off = banded[1], banded[0, 1:]
        value = float(planar.smallest_eigenvalue(diagonal, off))
        mode = None  # the minimiser needs the mode only to leave a saddle
        if value < 0:
            mode = np.ones(1) if self.size == 1 else eigh_tridiagonal(
                diagonal, off, select='i', select_range=(0, 0))[1][:, 0]
        return value, mode, np.max(np.abs(diagonal))

    def result(self, x):
        return x, (planar.points_linear if self.linear else planar.points)(self.chain, x)


class _Spatial:
    """3-DoF chain: x = joint angles flattened (3n,)."""

    linear = False

    def __init__(self, chain, field_t, gravity_m_s2, loads=()):
        self.chain = chain
        self.field, self.gravity, self.loads = field_t, gravity_m_s2, tuple(loads)
        self.levers = spatial.gravity_levers(chain)
        self.size = 3 * chain.size
        self.k_floor = max(1e-9 * np.max(chain.stiffness_n_m), 1e-300)
        self._key, self._value = None, None

    def evaluate(self, x):
        """Return the Evaluation at x, remembering the last one."""
        # The minimiser never changes an array in place: the same object is the same point.
        # A line search's trial is evaluated in full: it is usually the next iterate, and a
        # second pass over the chain costs more than the Hessian it would save.
        if x is not self._key:
            self._key, self._value = x, spatial.evaluate(
                self.chain, x.reshape(-1, 3), self.field, self.gravity, True, self.levers,
                self.loads)
        return self._value

    def energy(self, x):
        return self.evaluate(x).energy_j

    def gradient(self, x):
        return self.evaluate(x).gradient.reshape(-1)

    def torque_scale(self, x):
        return max(self.evaluate(x).largest_torque_n_m, self.k_floor)

    def newton_step(self, x, g):
        return _dense_newton_step(self.evaluate(x).hessian, g)

    def smallest_eigen(self, x):
        return _dense_smallest_eigen(self.evaluate(x).hessian)

    def result(self, x):
        return x.reshape(-1, 3), self.evaluate(x).points_m


class _SpatialLinear:
    """3-DoF small-angle model: the energy's quadratic Taylor model about q = 0."""

    linear = True

    def __init__(self, chain, field_t, gravity_m_s2, loads=()):
        self.chain, self.loads = chain, tuple(loads)
        self.size = 3 * chain.size
        straight = spatial.evaluate(chain, np.zeros((chain.size, 3)), field_t, gravity_m_s2,
                                    loads=loads)
        self.u0, self.g0 = straight.energy_j, straight.gradient.reshape(-1)
        self.h0, self.load_scale = straight.hessian, np.max(np.abs(straight.gradient))

    def energy(self, x):
        return self.u0 + self.g0 @ x + 0.5 * x @ self.h0 @ x

    def gradient(self, x):
        return self.g0 + self.h0 @ x

    def torque_scale(self, x):
        return max(self.load_scale, np.max(np.abs(self.h0 @ x)), 1e-300)

    def newton_step(self, x, g):
        return _dense_newton_step(self.h0, g)

    def smallest_eigen(self, x):
        return _dense_smallest_eigen(self.h0)

    def result(self, x):
        return x.reshape(-1, 3), spatial.points_linear(self.chain, x.reshape(-1, 3))


def _dense_newton_step(h, g):
    """Return the Newton step -H^-1 g, shifting an indefinite H just past positive."""
    factor, info = potrf(h, lower=True, clean=False)
    if info == 0:  # positive definite: the plain Newton step
        return -potrs(factor, g, lower=True)[0]
    # Indefinite (an obtuse magnet, a saddle nearby): shift just past the most negative
    # eigenvalue rather than searching for a shift that factorises.
    lowest = eigh(h, eigvals_only=True, subset_by_index=[0, 0], check_finite=False)[0]
    shift = -lowest + 1e-6 * max(np.max(np.abs(np.diag(h))), 1e-300)
    return -np.linalg.solve(h + shift * np.eye(len(g)), g)


def _dense_smallest_eigen(h):
    """Return (smallest eigenvalue, its eigenvector, the Hessian's diagonal scale)."""
    values, vectors = eigh(h, subset_by_index=[0, 0], check_finite=False)
    return float(values[0]), vectors[:, 0], np.max(np.abs(np.diag(h)))


def compile_kernels():
    """
    Compile (or load from numba's cache) the compiled passes, once per process.

    solve() calls it before its clock starts; call it ahead to keep the first solve's wall
    time down too (20 s on a fresh machine, 0.2 s from the cache; make venv builds the cache:
    scripts/build_kernels.py).
    """
    if _COMPILED:
        return
    one = np.ones(1)
    planar.evaluate(one, one, one, one, False, True)
    planar.smallest_eigenvalue(one, np.zeros(0))
    chain = Chain(one, np.ones((1, 3)), np.ones((1, 3)), one, one, np.zeros(3), np.eye(3))
    evaluation = spatial.evaluate(chain, np.zeros((1, 3)), np.zeros(3))
    for minimiser, x in ((_Spatial(chain, np.zeros(3), np.zeros(3)), np.zeros(3)),
                         (_Planar(chain, np.zeros(3), np.zeros(3)), np.zeros(1))):
        _minimise_compiled(minimiser, x, 1e-9, 1, np.inf, np.inf)
    two = Chain(np.ones(2), np.ones((2, 3)), np.ones((2, 3)), np.ones(2), np.ones(2),
                np.zeros(3), np.eye(3), np.array([0, 1]))
    loads = link_loads.of_chain(two, dipoles=True)
    for hessian in (False, True):   # the interaction projected in both joint models
        planar.project_loads(two, np.zeros(2), loads, hessian)
        spatial.evaluate(two, np.zeros((2, 3)), np.zeros(3), hessian=hessian, loads=loads)
    spatial_newton.sensitivities(evaluation.rotations, evaluation.axes, evaluation.points_m,
                                 evaluation.distal_moments, evaluation.hessian, np.zeros(3),
                                 np.arange(3))
    _COMPILED.append(True)


def estimate_memory_bytes(links, dof=1, dipole_pairs=0):
    """
    Return the estimated peak memory of a solve's arrays, bytes.

    Dense Hessians in the joint angles are (N, N) doubles with N = 3 n (3-DoF) or n (planar
    with dipoles: otherwise it is tridiagonal); the magnets' interaction adds its (6n, 6n)
    Hessian in moments and centres and more (_DIPOLE_COPIES: an over-estimate since the
    projection was compiled, kept as the time limit's measure).

    :param links: number of links n
    :param dof: 1 (planar) or 3
    :param dipole_pairs: interacting dipole pairs (Chain.interacting_pair_count(); 0 without
        the interaction)
    """
    n = int(links)
    size = 3 * n if dof == 3 else n
    dense = dof == 3 or dipole_pairs > 0
    estimate = _BYTES_PER_LINK * n + (8 * _DENSE_COPIES * size ** 2 if dense else 0)
    if dipole_pairs > 0:
        estimate += (8 * (6 * n) ** 2 + 8 * (_DIPOLE_COPIES - 1) * 6 * n * size
                     + _DIPOLE_BYTES_PER_PAIR * int(dipole_pairs))
    return estimate


def check_size(links, dof=1, dipole_pairs=0):
    """
    Refuse a problem too large to answer within the time limit (MAX_LINKS, MAX_ESTIMATED_BYTES).

    :param links: number of links n
    :param dof: 1 (planar) or 3
    :param dipole_pairs: interacting dipole pairs (0 without the interaction)
    :raises ProblemTooLarge: saying which limit and by how much
    """
    if dof not in (1, 3):
        raise ValueError(f'dof {dof} is not 1 or 3')
    model = {1: 'planar', 3: '3-DoF'}[dof]
    if links > MAX_LINKS[dof]:
        raise ProblemTooLarge(f'{links} links: the {model} model solves at most '
                              f'{MAX_LINKS[dof]} (use fewer sublinks)')
    estimate = estimate_memory_bytes(links, dof, dipole_pairs)
    if estimate > MAX_ESTIMATED_BYTES:
        terms = f' with {dipole_pairs} interacting dipole pairs' if dipole_pairs else ''
        raise ProblemTooLarge(
            f'{links} links{terms} in the {model} model need an estimated '
            f'{estimate / 2 ** 20:,.0f} MiB of dense arrays, more than the '
            f'{MAX_ESTIMATED_BYTES / 2 ** 20:.0f} MiB limit (use fewer sublinks)')


def _blas_threads(size):
    """Return a context that keeps BLAS on one thread for a dense problem of this size."""
    if not SINGLE_THREAD_SIZES[0] <= size <= SINGLE_THREAD_SIZES[1]:
        return contextlib.nullcontext()
    if not _BLAS:
        _BLAS.append(ThreadpoolController())
    return _BLAS[0].limit(limits=1, user_api='blas')


def _shifted_solve(solve_with_shift, diagonal, g):
    """Return -H^-1 g, shifting H by a growing multiple of I until it factorises."""
    scale = max(np.max(np.abs(diagonal)), 1e-300)
    shift = 0.0
    for _ in range(40):
        try:
            return -solve_with_shift(shift)
        except LinAlgError:
            shift = max(shift * 10.0, 1e-8 * scale)
    return -g / scale


def _minimise(problem, x, tol, max_iterations, time_limit_s, deadline):
    """
    Return (x, reason, iterations, residual, stability or None) of a damped Newton.

    The deadline (time.monotonic()) is checked before every Newton step and every trial of
    its line search: the run overshoots it by at most one evaluation or factorisation, which
    check_size keeps to a fraction of a second.
    """
    out_of_time = f'no convergence within the {time_limit_s:g} s limit'
    iterations = escapes = 0
    while True:
        g = problem.gradient(x)
        residual = float(np.abs(g).max() / problem.torque_scale(x))
        if not np.isfinite(residual):
            return x, 'non-finite gradient', iterations, residual, None
        if residual <= tol:
            value, mode, diag_scale = problem.smallest_eigen(x)
            if (value < -1e-9 * diag_scale and escapes < MAX_SADDLE_ESCAPES
                    and not problem.linear):
                escapes += 1
                x = x + ESCAPE_STEP_RAD * np.sign(mode.sum() or 1.0) * mode / np.max(
                    np.abs(mode))
                continue
            return x, 'converged' + (f' after leaving {escapes} saddle(s)' if escapes
                                     else ''), iterations, residual, value
        if iterations >= max_iterations:
            return x, f'no convergence in {max_iterations} iterations', iterations, \
                residual, None
        if time.monotonic() > deadline:
            return x, out_of_time, iterations, residual, None
        iterations += 1
        step = problem.newton_step(x, g)
        biggest = np.abs(step).max()
        if biggest > MAX_STEP_RAD and not problem.linear:  # a quadratic needs no cap
            step *= MAX_STEP_RAD / biggest
        u0, slope = problem.energy(x), float(g @ step)
        alpha, contact = 1.0, None
        while alpha > 1e-12:
            if time.monotonic() > deadline:  # a line search evaluates a dense Hessian per trial
                return x, out_of_time, iterations, residual, None
            trial = x + alpha * step
            try:
                u = problem.energy(trial)
            except Contact as exc:  # not a place the rod can be: step shorter
                u, contact = np.inf, exc
            if u <= u0 + 1e-4 * alpha * slope:
                break
            if abs(u - u0) <= 1e-13 * abs(u0) and np.max(np.abs(
                    problem.gradient(trial))) < np.max(np.abs(g)):
                break  # energy changes are round-off here: let the gradient decide
            alpha *= 0.5
        else:
            if residual <= 1e3 * tol:
                return x, 'converged (at round-off)', iterations, residual, None
            return x, f'line search failed (residual {residual:.3g})' + (
                f': {contact}' if contact else ''), iterations, residual, None
        x = trial


def _minimise_compiled(problem, x, tol, max_iterations, time_limit_s, deadline):
    """
    Return _minimise's result for a chain without link loads, by the compiled Newton.

    The same steps (spatial_newton.minimise, planar_newton.minimise), run in calls of
    COMPILED_STEP_WORK / size^2 Newton steps (at least one) with the deadline checked before
    each call (none past it): a call is well under a millisecond at any size a call holds
    more than one step.
    """
    steps = max(1, COMPILED_STEP_WORK // problem.size ** 2)
    newton = (MAX_STEP_RAD, MAX_SADDLE_ESCAPES, ESCAPE_STEP_RAD)
    if isinstance(problem, _Spatial):
        chain = problem.chain
        arguments = (chain.base_rotation, chain.base_position_m, chain.lengths_m,
                     np.ascontiguousarray(chain.moments_a_m2, dtype=float), problem.levers,
                     chain.stiffness_n_m, problem.field, problem.gravity, tol, problem.k_floor,
                     max_iterations)
        minimise = spatial_newton.minimise
    else:
        arguments = (problem.k, problem.a, problem.b, problem.load_scale, tol,
                     problem.k_floor, max_iterations)
        minimise = planar_newton.minimise
    iterations = escapes = 0
    while True:
        x, status, iterations, escapes, residual, stability = minimise(
            x, *arguments, iterations, escapes, 0 if time.monotonic() > deadline else steps,
            *newton)
        if status != spatial_newton.RUNNING:
            break
        if time.monotonic() > deadline:
            return x, f'no convergence within the {time_limit_s:g} s limit', iterations, \
                residual, None
    if status == spatial_newton.CONVERGED:
        return x, 'converged' + (f' after leaving {escapes} saddle(s)' if escapes else ''), \
            iterations, residual, float(stability)
    reason = {spatial_newton.NON_FINITE: 'non-finite gradient',
              spatial_newton.OUT_OF_ITERATIONS: f'no convergence in {max_iterations} iterations',
              spatial_newton.AT_ROUND_OFF: 'converged (at round-off)',
              spatial_newton.LINE_SEARCH_FAILED: f'line search failed (residual {residual:.3g})'}
    return x, reason[status], iterations, residual, None


def solve(chain, field_t, gravity_m_s2=(0.0, 0.0, 0.0), dof=1, initial=None, tol=1e-9,
          max_iterations=500, time_limit_s=10.0, linear=False, dipoles=False):
    """
    Return the Equilibrium of a chain.

    :param chain: a Chain (chain.py)
    :param field_t: (3,) uniform field, tesla, world frame
    :param gravity_m_s2: (3,) gravity, world frame (zero: no gravity)
    :param dof: 1 (planar joints) or 3 (bend, bend, twist)
    :param initial: the previous state to start from: (n,) link angles for dof 1, (n, 3)
        joint angles for dof 3, rad
    :param tol: converged when max |dU/dq| <= tol * the largest torque in the balance
    :param linear: small-angle model: the energy's quadratic Taylor model about the straight
        state and linearised kinematics, one linear solve; no minimum exists when a magnet
        is at an obtuse angle to the field, and the result says so
    :param dipoles: magnet-to-magnet interaction: every link is a point dipole at its centre
        acting on the links of other segments (a segment is one magnet)
    :param time_limit_s: wall-clock limit, s, from the start of the solve (numba's one-off
        compilation excepted): the result then says it did not converge; the run overshoots
        it by at most one Newton step (a fraction of a second at the largest sizes)
    :raises ValueError: non-finite field or gravity, an initial state of the wrong shape,
        the planar linearised model with dipoles (use dof 3)
    :raises ProblemTooLarge: more links than MAX_LINKS[dof], or an estimated memory beyond
        MAX_ESTIMATED_BYTES (check_size)
    """
    n = chain.size
    if dof not in (1, 3):
        raise ValueError(f'dof {dof} is not 1 or 3')
    field_t = np.asarray(field_t, dtype=float).reshape(-1)
    gravity_m_s2 = np.asarray(gravity_m_s2, dtype=float).reshape(-1)
    if not (field_t.size == gravity_m_s2.size == 3 and np.all(np.isfinite(field_t))
            and np.all(np.isfinite(gravity_m_s2))):
        raise ValueError(f'field {field_t} T and gravity {gravity_m_s2} m/s^2 must be three '
                         'finite numbers each')
    if n == 0:
        return Equilibrium(np.zeros((0,) if dof == 1 else (0, 3)),
                           chain.base_position_m[None, :].copy(), True, 'nothing inserted',
                           0, 0.0, np.inf, 0.0)  # no degree of freedom: vacuously stable
    pair_count = chain.interacting_pair_count() if dipoles else 0
    check_size(n, dof, pair_count)
    compile_kernels()  # seconds on a fresh machine, not to be charged to a solve's limit
    deadline = time.monotonic() + time_limit_s
    # Without a pair (one segment) the interaction is nothing: not even the (empty) pair list,
    # which takes n^2 memory to build.
    loads = link_loads.of_chain(chain, dipoles)
    if dof == 1:
        if linear and dipoles:
            raise ValueError('the planar linearised model has no dipole interaction: use dof 3')
        problem = _Planar(chain, field_t, gravity_m_s2, linear, loads)
    else:
        problem = (_SpatialLinear if linear else _Spatial)(chain, field_t, gravity_m_s2,
                                                           loads)
    shape = (n,) if dof == 1 else (n, 3)
    x = np.zeros(shape) if initial is None else np.array(initial, dtype=float)
    if x.shape != shape or not np.all(np.isfinite(x)):
        raise ValueError(f'initial angles must be finite numbers of shape {shape}')
    dense = dof == 3 or bool(loads)
    with _blas_threads(problem.size if dense else np.inf):
        try:
            return _solve(problem, x.reshape(-1), shape, tol, max_iterations, time_limit_s,
                          deadline)
        except Contact as exc:  # the start itself has two magnets in one place
            return Equilibrium(np.full(shape, np.nan), np.full((n + 1, 3), np.nan), False,
                               f'start state: {exc}', 0, np.nan, np.nan, np.nan)


def _solve(problem, x, shape, tol, max_iterations, time_limit_s, deadline):
    """Return the Equilibrium of a problem from x (see solve)."""
    points_shape = (problem.chain.size + 1, 3)
    if problem.linear:
        # The small-angle energy is quadratic: without a positive definite Hessian it has
        # no minimum at all, and descending it would run off to infinity.
        lowest = problem.smallest_eigen(x)[0]
        if lowest <= 0:
            return Equilibrium(np.full(shape, np.nan), np.full(points_shape, np.nan), False,
                               'linearised model has no minimum (Hessian not positive '
                               'definite)', 0, np.nan, lowest, np.nan)
    compiled = isinstance(problem, (_Spatial, _Planar)) and not (
        problem.loads or problem.linear)
    minimiser = _minimise_compiled if compiled else _minimise
    x, reason, iterations, residual, stability = minimiser(problem, x, tol, max_iterations,
                                                           time_limit_s, deadline)
    if not np.all(np.isfinite(x)):
        return Equilibrium(np.full(shape, np.nan), np.full(points_shape, np.nan), False,
                           reason, iterations, residual, np.nan, np.nan)
    if stability is None:
        stability = problem.smallest_eigen(x)[0]
    angles, points = problem.result(x)
    return Equilibrium(angles, points, reason.startswith('converged'), reason, iterations,
                       residual, stability, float(problem.energy(x)))


def small_angle_violation(eq, length_m, limit_rad=SMALL_ANGLE_LIMIT_RAD):
    """
    Return why a small-angle (linear) Equilibrium is outside the model's range, or None.

    Outside: a link turned more than limit_rad from the insertion direction (planar: its
    absolute angle; 3-DoF: the sum of the joint angles up to it, as the linearised
    kinematics add them). The linear solve still converges there, but its answer is not
    the rod's: the linearised kinematics stretch a link by sqrt(1 + angle^2), so far out
    the tip lies further from the base than the rod is long.

    :param eq: an Equilibrium of solve(..., linear=True)
    :param length_m: the inserted length of the rod, m (for the message)
    """
    angles = np.asarray(eq.angles_rad, dtype=float)
    if not len(angles) or not np.all(np.isfinite(angles)):
        return None  # nothing inserted, or no minimum (its reason says so already)
    link = np.abs(angles) if angles.ndim == 1 else np.linalg.norm(
        np.cumsum(angles, axis=0), axis=1)
    worst = int(np.argmax(link))
    if link[worst] <= limit_rad:
        return None
    reach = float(np.linalg.norm(eq.points_m[-1] - eq.points_m[0]))
    return (f"outside the small-angle model's range: link {worst + 1} is turned "
            f'{link[worst]:.3g} rad from the insertion direction, more than the {limit_rad:g} '
            f'rad the model holds for (its tip is {reach * 1e3:.4g} mm from the base of a '
            f'{length_m * 1e3:.4g} mm rod): use the full model')


def solve_planar(chain, field_t, gravity_m_s2=(0.0, 0.0, 0.0), **options):
    """Return the Equilibrium with planar 1-DoF joints (see solve)."""
    return solve(chain, field_t, gravity_m_s2, dof=1, **options)
