"""Overlapping Allan variance (O'Keefe 2015, eq. 2.52) and recovery of gyro noise parameters.

For rate samples ``ω_k`` at interval ``τ₀`` the integrated angle is ``θ_k = τ₀ Σ_{i<k} ω_i``
(θ_0 = 0).  For a cluster time ``τ = m τ₀`` the overlapping Allan variance is::

    σ²(τ) = 1 / (2 τ² (L − 2m)) Σ_{k=0}^{L−2m−1} (θ_{k+2m} − 2 θ_{k+m} + θ_k)²

with ``L`` the number of angle samples.  For the Farrenkopf gyro model (see
:mod:`lightcurve.css.gyro`) ``σ²(τ) = N²/τ + K² τ/3`` with ``N = σ_v`` (angle random walk,
slope −½ in log-log, read at τ = 1 s) and ``K = σ_u`` (rate random walk, slope +½, read at
τ = 3 s).  :func:`fit_arw_rrw` fits both by weighted linear least squares in σ².
"""

from __future__ import annotations

import numpy as np

__all__ = ["allan_variance", "fit_arw_rrw", "cluster_sizes"]


def cluster_sizes(n_samples: int, n_points: int = 40, max_fraction: float = 0.1) -> np.ndarray:
    """Log-spaced unique cluster sizes m from 1 to ``max_fraction`` of the samples."""
    mmax = max(1, int(n_samples * max_fraction))
    return np.unique(np.round(np.logspace(0, np.log10(mmax), n_points)).astype(int))


def allan_variance(rate, tau0: float, m=None):
    """Overlapping Allan variance of rate samples.

    Parameters
    ----------
    rate : array (K,) or (K, n)
        Rate samples (any unit u, e.g. rad/s), one column per axis.
    tau0 : float
        Sampling interval, s.
    m : array of int, optional
        Cluster sizes (default: :func:`cluster_sizes`).

    Returns
    -------
    tau (M,) s, avar (M,) or (M, n) in u², and the number of terms used per τ (M,).
    """
    w = np.asarray(rate, dtype=float)
    squeeze = w.ndim == 1
    if squeeze:
        w = w[:, None]
    if not tau0 > 0:
        raise ValueError("tau0 must be > 0")
    K = w.shape[0]
    m = cluster_sizes(K) if m is None else np.asarray(m, dtype=int)
    if np.any(m < 1) or np.any(2 * m >= K + 1):
        raise ValueError("cluster sizes must satisfy 1 <= m and 2 m <= number of samples")
    theta = np.vstack([np.zeros((1, w.shape[1])), np.cumsum(w, axis=0) * tau0])
    L = theta.shape[0]
    out = np.empty((m.size, w.shape[1]))
    nterms = np.empty(m.size, dtype=int)
    for i, mm in enumerate(m):
        d = theta[2 * mm:] - 2.0 * theta[mm:L - mm] + theta[:L - 2 * mm]
        tau = mm * tau0
        out[i] = np.sum(d * d, axis=0) / (2.0 * tau * tau * (L - 2 * mm))
        nterms[i] = L - 2 * mm
    tau = m * tau0
    return tau, (out[:, 0] if squeeze else out), nterms


def fit_arw_rrw(tau, avar, n_samples: int, tau0: float | None = None):
    """Fit ``σ²(τ) = N²/τ + K²τ/3`` to an Allan-variance curve.

    Weighted least squares in σ² with the approximate relative standard deviation of the
    overlapping estimator, ``1/√(2(n_samples/m − 1))`` (IEEE Std 952-1997, annex C), so that
    the noisy long-τ points count less (``tau0`` defaults to ``tau[0]``).  Returns ``(N, K)``: ARW in u·√s and RRW in u/√s for
    rates in unit u (rad/s → rad/√s, rad/s^{3/2}).
    """
    tau = np.asarray(tau, dtype=float)
    av = np.asarray(avar, dtype=float)
    m = np.maximum(1.0, tau / (tau[0] if tau0 is None else tau0))
    rel = 1.0 / np.sqrt(np.maximum(2.0 * (n_samples / m - 1.0), 1.0))
    sig = rel * av
    A = np.column_stack([1.0 / tau, tau / 3.0]) / sig[:, None]
    coef, *_ = np.linalg.lstsq(A, av / sig, rcond=None)
    N2, K2 = coef
    return float(np.sqrt(max(N2, 0.0))), float(np.sqrt(max(K2, 0.0)))
