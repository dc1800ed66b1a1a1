"""Scaled unscented transform: weights, sigma-point offsets, moments (numba kernels).

Julier (2002) in the parameterisation of Wan & van der Merwe (2000), as used by USQUE
(Crassidis & Markley 2003) and Bernard 2021 eq. 7.51–7.82:

* ``λ = α² (n + κ) − n``, spread ``γ = √(n + λ)``;
* mean weights ``W₀ᵐ = λ/(n+λ)``, ``Wᵢᵐ = 1/(2(n+λ))`` (i = 1…2n);
* covariance weights ``W₀ᶜ = W₀ᵐ + 1 − α² + β``, ``Wᵢᶜ = Wᵢᵐ``;
* offsets ``±σᵢ``, σᵢ the i-th column of the lower Cholesky factor of ``(n+λ) P`` — rows
  0…n−1 the "+" points, rows n…2n−1 the "−" points (the centre is not included).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .kalman import cholesky_nb

__all__ = ["unscented_weights_nb", "sigma_offsets_nb", "weighted_mean_cov_nb"]


@njit(cache=True)
def unscented_weights_nb(n, alpha, beta, kappa):
    """``(λ, Wᵐ (2n+1,), Wᶜ (2n+1,))`` of the scaled unscented transform (module docstring;
    λ of Bernard eq. 7.64).

    The caller checks ``n ≥ 1``, ``α > 0`` and ``n + λ > 0``.
    """
    lam = alpha * alpha * (n + kappa) - n
    c = n + lam
    wm = np.full(2 * n + 1, 0.5 / c)
    wm[0] = lam / c
    wc = wm.copy()
    wc[0] = wm[0] + 1.0 - alpha * alpha + beta
    return lam, wm, wc


@njit(cache=True)
def sigma_offsets_nb(P, c):
    """Offsets (2n, n) ``±σᵢ``, σᵢ the columns of chol(c P) with ``c = n + λ`` → ``(off, ok)``
    (Bernard eq. 7.51–7.53, 7.62–7.63).

    ``ok`` False (offsets zero) when ``c P`` is not positive definite (:func:`cholesky_nb`).
    ``P`` is symmetrised first (only its lower triangle is read after that).
    """
    n = P.shape[0]
    A = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            A[i, j] = c * (0.5 * (P[i, j] + P[j, i]))
    L, ok = cholesky_nb(A)
    off = np.zeros((2 * n, n))
    if not ok:
        return off, False
    for i in range(n):
        for j in range(n):
            off[i, j] = L[j, i]
            off[n + i, j] = -L[j, i]
    return off, True


@njit(cache=True)
def weighted_mean_cov_nb(X, wm, wc):
    """``x̄ = Σ Wᵢᵐ Xᵢ`` and ``Σ Wᵢᶜ (Xᵢ − x̄)(Xᵢ − x̄)ᵀ`` (symmetric) of the rows of X (N, d)."""
    N, d = X.shape
    mean = np.zeros(d)
    for i in range(N):
        for j in range(d):
            mean[j] += wm[i] * X[i, j]
    C = np.zeros((d, d))
    for i in range(N):
        for a in range(d):
            xa = wc[i] * (X[i, a] - mean[a])
            for b in range(a + 1):
                C[a, b] += xa * (X[i, b] - mean[b])
    for a in range(d):
        for b in range(a):
            C[b, a] = C[a, b]
    return mean, C
