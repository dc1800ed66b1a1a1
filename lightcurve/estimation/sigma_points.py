"""Scaled unscented sigma points, weights and the unscented transform (generic on vectors).

Scaled unscented transform of Julier (2002) in the parameterisation of Wan & van der Merwe
(2000), as used by USQUE (Crassidis & Markley 2003) and Bernard (2021) eq. 7.51–7.82:

* ``λ = α² (n + κ) − n``, spread ``γ = √(n + λ)``;
* mean weights ``W₀ᵐ = λ/(n+λ)``, ``Wᵢᵐ = 1/(2(n+λ))`` (i = 1…2n);
* covariance weights ``W₀ᶜ = W₀ᵐ + 1 − α² + β``, ``Wᵢᶜ = Wᵢᵐ``;
* points ``χ₀ = x``, ``χᵢ = x + σᵢ``, ``χₙ₊ᵢ = x − σᵢ`` with σᵢ the i-th column of the lower
  Cholesky factor of ``(n+λ) P`` (row order: centre, the n "+" points, the n "−" points).

Everything here is generic: for an attitude filter the vector is the GRP error state (plus
rate and extra states); mapping offsets to quaternions (within Bernard eq. 7.51–7.82) is the
attitude filter's job. Augmented states (process and measurement noise appended with zero
mean, Bernard eq. 7.83–7.87) are built with :func:`augment` and taken apart with
:func:`split_augmented`.

Functions that need a matrix square root return an ``ok`` flag instead of raising or
producing NaN when the covariance is not positive definite.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.kalman import backward_nb, forward_nb
from ..core.sigma_points import sigma_offsets_nb, unscented_weights_nb
from .kalman import UpdateInfo, safe_cholesky, symmetrize

__all__ = [
    "UnscentedWeights",
    "unscented_weights",
    "sigma_offsets",
    "sigma_points",
    "unscented_mean",
    "unscented_covariance",
    "unscented_cross_covariance",
    "UTResult",
    "unscented_transform",
    "unscented_update",
    "augment",
    "split_augmented",
]


@dataclass(frozen=True)
class UnscentedWeights:
    """Weights of the scaled unscented transform for an ``n``-dimensional vector.

    Attributes
    ----------
    n : int
        Dimension of the (possibly augmented) vector.
    alpha, beta, kappa : float
        Spread, prior-knowledge (2 is optimal for Gaussians) and secondary scaling parameters.
    lam : float
        ``λ = α²(n + κ) − n``.
    wm, wc : ndarray (2n+1,)
        Mean and covariance weights (``wm`` sums to 1).
    """

    n: int
    alpha: float
    beta: float
    kappa: float
    lam: float
    wm: np.ndarray
    wc: np.ndarray

    @property
    def gamma(self) -> float:
        """Spread ``√(n + λ)`` multiplying the Cholesky factor of P."""
        return float(np.sqrt(self.n + self.lam))

    @property
    def n_points(self) -> int:
        """Number of sigma points, ``2n + 1``."""
        return 2 * self.n + 1


def unscented_weights(n, alpha=1.0, beta=2.0, kappa=0.0) -> UnscentedWeights:
    """Weights of the scaled unscented transform (module docstring for the formulas).

    Parameters
    ----------
    n : int
        Vector dimension, ≥ 1.
    alpha : float
        Spread, > 0 (1e-3 … 1 are common; the thesis cases use the filter's configured value).
    beta : float
        Prior-knowledge parameter (2 for Gaussian priors).
    kappa : float
        Secondary scaling; ``n + κ = 3`` is Julier & Uhlmann's choice for Gaussians.

    Raises
    ------
    ValueError
        If ``n < 1``, ``alpha <= 0`` or ``n + λ <= 0`` (the spread would be imaginary).
    """
    n = int(n)
    if n < 1:
        raise ValueError(f"dimension n must be >= 1, got {n}")
    alpha = float(alpha)
    beta = float(beta)
    kappa = float(kappa)
    if not alpha > 0.0 or not np.isfinite(alpha):
        raise ValueError(f"alpha must be finite and > 0, got {alpha}")
    if not (np.isfinite(beta) and np.isfinite(kappa)):
        raise ValueError(f"beta and kappa must be finite, got beta={beta}, kappa={kappa}")
    c = alpha * alpha * (n + kappa)
    if not c > 0.0:
        raise ValueError(f"n + lambda = alpha^2 (n + kappa) must be > 0; got {c} "
                         f"(n={n}, alpha={alpha}, kappa={kappa})")
    lam, wm, wc = unscented_weights_nb(n, alpha, beta, kappa)
    return UnscentedWeights(n=n, alpha=alpha, beta=beta, kappa=kappa, lam=lam, wm=wm, wc=wc)


def _check_weights(weights, n):
    if not isinstance(weights, UnscentedWeights):
        raise ValueError("weights must be an UnscentedWeights (see unscented_weights)")
    if weights.n != n:
        raise ValueError(f"weights are for dimension {weights.n}, the covariance is {n}x{n}")


def sigma_offsets(P, weights):
    """The 2n offsets ``±σᵢ`` with σᵢ the columns of chol((n+λ) P).

    Parameters
    ----------
    P : array_like (n, n)
        Covariance (for USQUE: ``P + Q`` of the error state, Crassidis & Markley 2003).
    weights : UnscentedWeights

    Returns
    -------
    offsets : ndarray (2n, n) or None
        Rows 0…n−1 are ``+σᵢ``, rows n…2n−1 are ``−σᵢ``; None when P is not positive definite.
    ok : bool
    """
    P = np.asarray(P, dtype=float)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise ValueError(f"P must be square (n, n), got {P.shape}")
    n = P.shape[0]
    _check_weights(weights, n)
    if not np.all(np.isfinite(P)):
        return None, False
    off, ok = sigma_offsets_nb(np.ascontiguousarray(P), n + weights.lam)
    return (off, True) if ok else (None, False)


def sigma_points(x, P, weights):
    """Sigma points ``χ`` (2n+1, n) about ``x``: centre, ``x + σᵢ``, ``x − σᵢ``.

    Returns ``(chi, ok)``; ``chi`` is None when P is not positive definite.
    """
    x = np.asarray(x, dtype=float).ravel()
    off, ok = sigma_offsets(P, weights)
    if not ok:
        return None, False
    if x.shape[0] != weights.n:
        raise ValueError(f"x has {x.shape[0]} components, weights are for n = {weights.n}")
    return np.concatenate([x[None, :], x[None, :] + off], axis=0), True


def _check_points(Y, weights, name="Y"):
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    if Y.ndim != 2 or Y.shape[0] != weights.n_points:
        raise ValueError(f"{name} must have shape ({weights.n_points}, m), got {Y.shape}")
    return Y


def unscented_mean(Y, weights):
    """Weighted mean ``Σ Wᵢᵐ Yᵢ`` of transformed sigma points ``Y`` (2n+1, m) → (m,)."""
    Y = _check_points(Y, weights)
    return weights.wm @ Y


def unscented_covariance(Y, mean, weights, noise_cov=None):
    """``Σ Wᵢᶜ (Yᵢ − ȳ)(Yᵢ − ȳ)ᵀ (+ noise_cov)``, symmetrised → (m, m)."""
    Y = _check_points(Y, weights)
    D = Y - np.asarray(mean, dtype=float).reshape(1, -1)
    C = (D * weights.wc[:, None]).T @ D
    if noise_cov is not None:
        C = C + np.atleast_2d(np.asarray(noise_cov, dtype=float))
    return symmetrize(C)


def unscented_cross_covariance(X, x_mean, Y, y_mean, weights):
    """``Σ Wᵢᶜ (Xᵢ − x̄)(Yᵢ − ȳ)ᵀ`` → (n, m)."""
    X = _check_points(X, weights, "X")
    Y = _check_points(Y, weights)
    DX = X - np.asarray(x_mean, dtype=float).reshape(1, -1)
    DY = Y - np.asarray(y_mean, dtype=float).reshape(1, -1)
    return (DX * weights.wc[:, None]).T @ DY


@dataclass(frozen=True)
class UTResult:
    """Result of :func:`unscented_transform` (arrays are None when ``ok`` is False)."""

    mean: np.ndarray | None
    cov: np.ndarray | None
    cross: np.ndarray | None
    chi: np.ndarray | None
    Y: np.ndarray | None
    ok: bool


def unscented_transform(f, x, P, weights, noise_cov=None):
    """Propagate ``N(x, P)`` through ``f`` with the scaled unscented transform.

    Parameters
    ----------
    f : callable
        Vectorised map: ``f(chi)`` with ``chi`` (2n+1, n) returns (2n+1, m) (or (2n+1,)).
    x, P : mean (n,) and covariance (n, n).
    weights : UnscentedWeights for dimension n.
    noise_cov : (m, m), optional
        Additive noise covariance added to the output covariance.

    Returns
    -------
    UTResult
        ``mean`` (m,), ``cov`` (m, m), ``cross`` = cov(x, y) (n, m), the sigma points ``chi``
        and their images ``Y``; ``ok`` False (and None arrays) when P is not positive definite
        or ``f`` returned non-finite values.
    """
    chi, ok = sigma_points(x, P, weights)
    if not ok:
        return UTResult(None, None, None, None, None, False)
    Y = np.asarray(f(chi), dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    if Y.shape[0] != chi.shape[0]:
        raise ValueError(f"f must return one row per sigma point ({chi.shape[0]}), "
                         f"got shape {Y.shape}")
    if not np.all(np.isfinite(Y)):
        return UTResult(None, None, None, chi, Y, False)
    ym = unscented_mean(Y, weights)
    Pyy = unscented_covariance(Y, ym, weights, noise_cov)
    Pxy = unscented_cross_covariance(chi, chi[0], Y, ym, weights)  # Σ Wᵐ χ = χ₀ = x
    return UTResult(ym, Pyy, Pxy, chi, Y, True)


def unscented_update(x, P, X, Y, y, weights, R=None):
    """Unscented Kalman measurement update from propagated sigma points.

    Parameters
    ----------
    x : (n,) predicted mean (usually ``Σ Wᵐ X``; for USQUE the GRP error mean).
    P : (n, n) predicted covariance.
    X : (2N+1, n) predicted sigma points of the state (N may exceed n for augmented points;
        only the first n columns are used).
    Y : (2N+1, m) predicted measurements of the same points.
    y : (m,) measurement.
    weights : UnscentedWeights for the sigma-point dimension N.
    R : (m, m), float or (m,), optional
        Additive measurement-noise covariance (omit when it is already in the augmented
        points).

    Returns
    -------
    x_post, P_post, info : as :func:`lightcurve.estimation.kalman.joseph_update`;
        ``P⁺ = P − K Pyy Kᵀ`` (the USQUE update), symmetrised; on failure the prior is
        returned unchanged with ``info.ok = False``.
    """
    x = np.asarray(x, dtype=float).ravel()
    P = np.asarray(P, dtype=float)
    n = x.shape[0]
    X = _check_points(X, weights, "X")[:, :n]
    Y = _check_points(Y, weights)
    y = np.atleast_1d(np.asarray(y, dtype=float))
    m = Y.shape[1]
    if y.shape != (m,):
        raise ValueError(f"y must have shape ({m},), got {y.shape}")
    ym = unscented_mean(Y, weights)
    Rm = None
    if R is not None:
        Rm = np.asarray(R, dtype=float)
        Rm = float(Rm) * np.eye(m) if Rm.ndim == 0 else (np.diag(Rm) if Rm.ndim == 1 else Rm)
    Pyy = unscented_covariance(Y, ym, weights, Rm)
    nu = y - ym
    if not np.all(np.isfinite(nu)):
        return x.copy(), P.copy(), UpdateInfo(nu, Pyy, np.nan, False, None,
                                              "non-finite innovation")
    L, ok = safe_cholesky(Pyy)
    if not ok:
        return x.copy(), P.copy(), UpdateInfo(nu, Pyy, np.nan, False, None,
                                              "innovation covariance is not positive definite")
    Pxy = unscented_cross_covariance(X, x, Y, ym, weights)
    if m == 1:
        # scalar measurement: the Cholesky solves are divisions (no BLAS thread-pool wake-up;
        # see estimation.kalman._gain)
        ell = L[0, 0]
        K = (Pxy / ell) / ell
        w = nu / ell
    else:
        K = np.array([backward_nb(L, forward_nb(L, np.ascontiguousarray(r))) for r in Pxy])
        w = forward_nb(L, np.ascontiguousarray(nu))
    x_new = x + K @ nu
    P_new = symmetrize(P - K @ Pyy @ K.T)
    if not (np.all(np.isfinite(x_new)) and np.all(np.isfinite(P_new))):
        return x.copy(), P.copy(), UpdateInfo(nu, Pyy, np.nan, False, None,
                                              "non-finite posterior")
    return x_new, P_new, UpdateInfo(nu, Pyy, float(w @ w), True, K)


def augment(x, P, *noise_covs):
    """Append zero-mean noise blocks to a state: ``x_a = [x; 0; …]``, ``P_a = blkdiag(P, Q, R…)``.

    Parameters
    ----------
    x : (n,) state mean; P : (n, n) its covariance;
    *noise_covs : square matrices (or scalars / 1-D diagonals) of the noise terms to augment
        (for USQUE: process noise then measurement noise).

    Returns
    -------
    x_a : ndarray (n + Σq,), P_a : ndarray, sizes : tuple of int (n, q₁, q₂, …)
        ``sizes`` is what :func:`split_augmented` needs.
    """
    x = np.asarray(x, dtype=float).ravel()
    P = np.asarray(P, dtype=float)
    if P.shape != (x.shape[0], x.shape[0]):
        raise ValueError(f"P must have shape {(x.shape[0],) * 2}, got {P.shape}")
    blocks = [P]
    for i, Q in enumerate(noise_covs):
        Q = np.asarray(Q, dtype=float)
        if Q.ndim == 0:
            Q = Q.reshape(1, 1)
        elif Q.ndim == 1:
            Q = np.diag(Q)
        if Q.ndim != 2 or Q.shape[0] != Q.shape[1]:
            raise ValueError(f"noise covariance {i} must be square, got {Q.shape}")
        blocks.append(Q)
    sizes = tuple(b.shape[0] for b in blocks)
    N = sum(sizes)
    Pa = np.zeros((N, N))
    i0 = 0
    for b in blocks:
        k = b.shape[0]
        Pa[i0:i0 + k, i0:i0 + k] = b
        i0 += k
    xa = np.concatenate([x, np.zeros(N - x.shape[0])])
    return xa, Pa, sizes


def split_augmented(chi, sizes):
    """Split augmented sigma points (…, Σsizes) into views per block (state, noise₁, …)."""
    chi = np.asarray(chi)
    sizes = tuple(int(s) for s in sizes)
    if chi.shape[-1] != sum(sizes):
        raise ValueError(f"last axis has {chi.shape[-1]} components, sizes sum to {sum(sizes)}")
    out = []
    i0 = 0
    for s in sizes:
        out.append(chi[..., i0:i0 + s])
        i0 += s
    return tuple(out)
