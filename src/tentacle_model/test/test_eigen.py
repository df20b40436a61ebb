"""The smallest eigenvalue without the spectrum: against LAPACK's, on hard spectra too."""

import numpy as np
import pytest
from tentacle_model import eigen


def spectrum(kind, n, rng):
    """Return n eigenvalues of a kind that is hard for one method or another."""
    if kind == 'spread':       # of both signs
        return rng.normal(size=n)
    if kind == 'scales':       # positive, over nine decades
        return np.abs(rng.normal(size=n)) * 10.0 ** rng.uniform(-6, 3, n)
    if kind == 'clusters':     # triples within 1e-12
        return np.resize(np.repeat(rng.normal(size=n), 3), n) + 1e-12 * rng.normal(size=n)
    values = np.linspace(1e-4, 3e-3, n)   # 'soft pair': a stiffness matrix's twin soft modes
    values[:2] = (3.9e-5, 4.2e-5)[:n]
    return values


@pytest.mark.parametrize('kind', ['spread', 'scales', 'clusters', 'soft pair'])
@pytest.mark.parametrize('n', [1, 2, 3, 15, 40])
def test_the_lowest_eigenvalue_is_lapacks_to_round_off(kind, n):
    rng = np.random.default_rng(n)
    for _ in range(20):
        q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        h = (q * spectrum(kind, n, rng)) @ q.T
        h = 0.5 * (h + h.T)
        everything = np.linalg.eigvalsh(h)
        norm = max(np.max(np.abs(everything)), 1e-300)
        assert eigen.lowest(h) == pytest.approx(everything[0], rel=0, abs=1e-14 * norm)
        # started near it (a neighbour's value): below it, above it (refused), far below
        for guess in (everything[0] - 1e-3 * norm, everything[0] + 1e-3 * norm,
                      everything[0] - 0.5 * norm):
            near = eigen.lowest(h, guess)
            assert near == pytest.approx(everything[0], rel=0, abs=1e-14 * norm)
        diagonal, off = eigen.tridiagonal(h)   # the reduction keeps the spectrum
        np.testing.assert_allclose(np.linalg.eigvalsh(np.diag(diagonal) + np.diag(off, 1)
                                                      + np.diag(off, -1)), everything,
                                   rtol=0, atol=1e-14 * norm)


def test_degenerate_matrices():
    assert eigen.lowest(np.zeros((4, 4))) == 0.0
    assert eigen.lowest(np.eye(5) * 2.5) == pytest.approx(2.5, rel=1e-15)
    assert eigen.lowest(np.array([[-3.0]])) == -3.0
    assert eigen.tridiagonal_lowest(np.array([1.0, 1.0]), np.array([0.0])) == 1.0


@pytest.mark.parametrize('n', [1, 2, 15, 40])
def test_cholesky_is_lapacks_and_refuses_what_is_not_positive_definite(n):
    rng = np.random.default_rng(n)
    a = rng.normal(size=(n, n))
    h = a @ a.T + n * np.eye(n)
    factor, positive = eigen.cholesky(h)
    assert positive
    np.testing.assert_allclose(np.tril(factor), np.linalg.cholesky(h), rtol=1e-12, atol=0)
    g = rng.normal(size=n)
    np.testing.assert_allclose(eigen.cholesky_solve(factor, g), np.linalg.solve(h, g),
                               rtol=1e-10)
    h[n - 1, n - 1] = -1.0   # an indefinite one, and one that is not a number
    assert not eigen.cholesky(h)[1]
    assert not eigen.cholesky(np.full((n, n), np.nan))[1]
