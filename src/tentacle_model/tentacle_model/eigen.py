"""
Small symmetric matrices: Cholesky, and the smallest eigenvalue without the rest of the spectrum.

A stability is a Hessian's smallest eigenvalue. LAPACK's whole spectrum (numba's eigvalsh,
dsyevd) takes 8 us for a 15 x 15 matrix: 40% of a 5-link 3-DoF equilibrium in batch. lowest:
Householder reduction to tridiagonal form (LAPACK's own first step), then the tridiagonal's
smallest eigenvalue by Laguerre's method on its characteristic polynomial (tridiagonal_
lowest), guarded by Sturm counts: the root to round-off of the matrix's norm, as LAPACK's
(3.1 us at 15 x 15). A few Lanczos steps from a neighbouring point's eigenvector were tried in
its place: a batch's Hessians have stiff modes far above the soft ones, and from a start 1e-4
off the eigenvector four steps leave a residual 10^3 times too large to certify the value.
"""

import numba
import numpy as np

EPS = np.finfo(float).eps
MAX_PASSES = 200   # O(n) passes over the tridiagonal (a few; bisection alone needs 60)


@numba.njit(cache=True)
def tridiagonal(h):
    """Return (diagonal (n,), off-diagonal (n - 1,)) of a symmetric H reduced by Householder."""
    a = h.copy()
    n = a.shape[0]
    u = np.empty(n)
    w = np.empty(n)
    for k in range(n - 2):
        m = n - k - 1   # the block below and right of (k, k), from row k + 1
        norm = 0.0
        for i in range(m):
            u[i] = a[k + 1 + i, k]
            norm += u[i] * u[i]
        norm = np.sqrt(norm)
        if norm == 0.0:
            continue
        alpha = -norm if u[0] >= 0.0 else norm
        u[0] -= alpha
        length = 0.0
        for i in range(m):
            length += u[i] * u[i]
        length = np.sqrt(length)
        for i in range(m):
            u[i] /= length
        # (I - 2 u u^T) A (I - 2 u u^T) = A - 2 u w^T - 2 w u^T, w = A u - (u^T A u) u
        c = 0.0
        for i in range(m):
            total = 0.0
            for j in range(m):
                total += a[k + 1 + i, k + 1 + j] * u[j]
            w[i] = total
            c += u[i] * total
        for i in range(m):
            w[i] -= c * u[i]
        for i in range(m):
            for j in range(m):
                a[k + 1 + i, k + 1 + j] -= 2.0 * (u[i] * w[j] + w[i] * u[j])
        a[k + 1, k] = a[k, k + 1] = alpha
    diagonal = np.empty(n)
    off = np.empty(max(n - 1, 0))
    for i in range(n):
        diagonal[i] = a[i, i]
        if i < n - 1:
            off[i] = a[i + 1, i]
    return diagonal, off


@numba.njit(cache=True, error_model='numpy')   # a zero divide is inf, not an exception
def tridiagonal_lowest(diagonal, off, below=np.nan):
    """
    Return the smallest eigenvalue of a symmetric tridiagonal matrix.

    Laguerre's method on det(T - x I) from Gershgorin's lower bound: for a polynomial whose
    roots are all real it rises monotonically to the smallest from anywhere left of it, in
    a few steps (exactly in one for a root of any multiplicity alone), where Newton's crawls
    from afar. A pass is the pivot recurrence of T - x I with its first two derivatives;
    its Sturm count guards the round-off at the end (an iterate past the root is bisected
    back).

    :param diagonal: (n,) diagonal
    :param off: (n - 1,) off-diagonal
    :param below: a guess just below the eigenvalue (a neighbouring matrix's, less a margin):
        Laguerre starts there if a Sturm count says it is below (else at Gershgorin's bound)
    """
    n = len(diagonal)
    lo, hi = np.inf, -np.inf
    for i in range(n):   # Gershgorin: every eigenvalue lies in [lo, hi]
        radius = (abs(off[i - 1]) if i > 0 else 0.0) + (abs(off[i]) if i < n - 1 else 0.0)
        lo = min(lo, diagonal[i] - radius)
        hi = max(hi, diagonal[i] + radius)
    scale = max(abs(lo), abs(hi), 1e-300)
    tiny = 1e-100 + 1e-30 * scale   # cubed, still a number
    close = 4.0 * EPS * scale
    if hi - lo <= close:   # a multiple of the identity, to round-off
        return lo
    x = lo
    if lo < below < hi and _count_below(diagonal, off, below, tiny) == 0:
        x = lo = below
    for _ in range(MAX_PASSES):
        pivot, first, second = 1.0, 0.0, 0.0
        below, g, curvature = 0, 0.0, 0.0
        for i in range(n):
            if i == 0:
                pivot, first, second = diagonal[0] - x, -1.0, 0.0
            else:
                b2 = off[i - 1] ** 2
                second = b2 * (second * pivot - 2.0 * first * first) / pivot ** 3
                first = -1.0 + b2 * first / (pivot * pivot)
                pivot = diagonal[i] - x - b2 / pivot
            if pivot == 0.0:
                pivot = -tiny   # a zero pivot: count x itself as above the eigenvalue
            if pivot < 0.0:
                below += 1
            ratio = first / pivot
            g += ratio                                  # (log det)'
            curvature += second / pivot - ratio * ratio  # (log det)''
        if below >= 1:   # past the root (round-off at the end): back between lo and it
            hi = x
            if hi - lo <= close:
                return 0.5 * (lo + hi)
            x = 0.5 * (lo + hi)
            continue
        lo = x
        spread = (n - 1) * (-n * curvature - g * g)
        step = -n / (g - np.sqrt(max(spread, 0.0)))
        if not step > close:   # converged (or not finite: x is the root to round-off)
            return min(lo + step, hi) if step > 0.0 else lo
        x = lo + step if lo + step < hi else 0.5 * (lo + hi)
    return 0.5 * (lo + hi)


@numba.njit(cache=True, error_model='numpy')
def _count_below(diagonal, off, x, tiny):
    """Return how many eigenvalues of the tridiagonal lie below x (Sturm: negative pivots)."""
    below = 0
    pivot = 1.0
    for i in range(diagonal.shape[0]):
        pivot = diagonal[i] - x - (off[i - 1] ** 2 / pivot if i > 0 else 0.0)
        if pivot == 0.0:
            pivot = -tiny
        if pivot < 0.0:
            below += 1
    return below


@numba.njit(cache=True)
def lowest(h, below=np.nan):
    """Return the smallest eigenvalue of a symmetric H (n, n); below: tridiagonal_lowest's."""
    diagonal, off = tridiagonal(h)
    return tridiagonal_lowest(diagonal, off, below)


@numba.njit(cache=True)
def cholesky_solve(factor, g):
    """Return x with L L^T x = g for a lower Cholesky factor L."""
    size = g.shape[0]
    x = np.empty(size)
    for i in range(size):   # L y = g, y in x
        total = g[i]
        for k in range(i):
            total -= factor[i, k] * x[k]
        x[i] = total / factor[i, i]
    for i in range(size - 1, -1, -1):   # L^T x = y, in place: x[i] needs y[i] and x[k > i]
        total = x[i]
        for k in range(i + 1, size):
            total -= factor[k, i] * x[k]
        x[i] = total / factor[i, i]
    return x


@numba.njit(cache=True)
def cholesky(h):
    """
    Return (L, True) with L L^T = H, L lower; (_, False) where H is not positive definite.

    Written out: numba's LAPACK dpotrf copies and checks its input, a third of a 15 x 15
    factorisation's time (a 3-DoF solve factorises some three a point); from some 25 rows
    LAPACK's blocked factorisation is faster.
    """
    n = h.shape[0]
    factor = np.zeros((n, n))
    for j in range(n):
        total = h[j, j]
        for k in range(j):
            total -= factor[j, k] * factor[j, k]
        if not total > 0.0:   # NaN too, as dpotrf
            return factor, False
        pivot = np.sqrt(total)
        factor[j, j] = pivot
        for i in range(j + 1, n):
            total = h[i, j]
            for k in range(j):
                total -= factor[i, k] * factor[j, k]
            factor[i, j] = total / pivot
    return factor, True
