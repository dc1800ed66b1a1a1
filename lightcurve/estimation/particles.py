"""Particle-filter machinery: log weights, normalisation, resampling, roughening, moments.

The checked object layer over the kernels of :mod:`lightcurve.core.particles` (where each
equation is implemented once): argument validation, ``rng`` handling, new output arrays.

Generic over the particle state (rows of an (N, d) float array). The bootstrap attitude
filter (Bernard 2021 tables 7.7–7.11) keeps its particles as quaternion + rate and feeds the
GRP/rate representation to :func:`roughen` and :func:`weighted_mean_cov`; the attitude-specific
mapping is not done here.

* Weights are kept as natural-log weights and normalised with log-sum-exp, so likelihoods of
  order 1e-300 (log weights near −1e4 and below) neither underflow nor produce NaN.
* Resampling returns *indices* into the particle array (``particles[idx]`` is the new cloud):
  systematic (Kitagawa 1996; one uniform shared by N equally spaced positions), stratified
  (one uniform per stratum) and multinomial (Bernard table 6.3; N independent uniforms).
  The uniforms come from the caller's ``numpy.random.Generator`` (or a seed); the O(N) merge
  is a ``numba.njit(cache=True)`` kernel, so results are bit-for-bit reproducible.
* Roughening (Gordon, Salmond & Smith 1993, the form used in Bernard table 7.9): after
  resampling add independent zero-mean Gaussian jitter to every component j with standard
  deviation ``σⱼ = 𝒢 Eⱼ N^(−1/d)``, where ``Eⱼ = maxᵢ xᵢⱼ − minᵢ xᵢⱼ`` is the range of
  component j over the cloud, N the number of particles, d the state dimension and 𝒢 the
  tuning constant (0.2 is a common choice).
"""

from __future__ import annotations

import numba
import numpy as np

from ..core import particles as core
from ..core.particles import logsumexp_nb
from ..errors import ConvergenceError
from .rng import as_generator

__all__ = [
    "logsumexp",
    "normalize_log_weights",
    "effective_sample_size",
    "effective_sample_size_log",
    "gaussian_log_likelihood",
    "update_log_weights",
    "systematic_resample",
    "stratified_resample",
    "multinomial_resample",
    "resample",
    "RESAMPLING_METHODS",
    "roughening_sigma",
    "roughen",
    "weighted_mean_cov",
    "logsumexp_nb",
    "systematic_resample_nb",
    "resample_sorted_nb",
    "add_gaussian_loglik_nb",
]

_LOG_2PI = float(np.log(2.0 * np.pi))


# --------------------------------------------------------------------------------------------
# Kernels (the one implementation lives in lightcurve.core.particles)
# --------------------------------------------------------------------------------------------

def systematic_resample_nb(w, u0, n_out):
    """Systematic resampling indices (n_out,) for non-negative weights ``w`` (need not sum to
    one), ``u0`` ∈ [0, 1) the single uniform (:func:`lightcurve.core.particles.
    systematic_resample_into`). Zero-weight particles are never selected; indices are
    non-decreasing."""
    idx = np.empty(int(n_out), dtype=np.int64)
    if not core.systematic_resample_into(w, float(u0), np.empty(w.shape[0]), idx):
        raise ValueError("weights must not all be zero")
    return idx


def resample_sorted_nb(w, u):
    """Indices for sorted uniforms ``u`` (ascending, in [0, 1)) against the cumulative of ``w``
    (:func:`lightcurve.core.particles.sorted_resample_into`); O(N + len(u))."""
    idx = np.empty(u.shape[0], dtype=np.int64)
    if not core.sorted_resample_into(w, np.ascontiguousarray(u, dtype=np.float64),
                                     np.empty(w.shape[0]), idx):
        raise ValueError("weights must not all be zero")
    return idx


@numba.njit(cache=True, parallel=True)
def add_gaussian_loglik_nb(logw, resid, Linv, const):
    """In place: ``logw[i] += const − ½ |Linv · resid[i]|²`` for every particle i (prange).

    The multivariate Gaussian measurement log-likelihood (Bernard eq. 6.56, in logs):
    ``resid`` (N, m) are measurement residuals ``y − h(xᵢ)``, ``Linv`` (m, m) the inverse of the
    lower Cholesky factor of R, ``const = −½ m log 2π − Σ log diag(L)``. Each particle is
    independent, so the parallel loop is deterministic.
    """
    N = resid.shape[0]
    m = resid.shape[1]
    for i in numba.prange(N):
        q = 0.0
        for a in range(m):
            z = 0.0
            for b in range(a + 1):
                z += Linv[a, b] * resid[i, b]
            q += z * z
        logw[i] += const - 0.5 * q


# --------------------------------------------------------------------------------------------
# Object layer
# --------------------------------------------------------------------------------------------

def _as_1d_float(a, name):
    a = np.ascontiguousarray(np.asarray(a, dtype=np.float64))
    if a.ndim != 1 or a.shape[0] == 0:
        raise ValueError(f"{name} must be a non-empty 1-D array, got shape {a.shape}")
    return a


def logsumexp(logw) -> float:
    """``log Σ exp(logwᵢ)`` (stable). −inf if every entry is −inf; ValueError on NaN."""
    a = _as_1d_float(logw, "logw")
    r = float(logsumexp_nb(a))
    if np.isnan(r):
        raise ValueError("log weights contain NaN")
    return r


def normalize_log_weights(logw):
    """Normalise log weights: returns ``(w, log_total)``.

    Parameters
    ----------
    logw : array_like (N,)
        Unnormalised natural-log weights (−inf allowed for impossible particles).

    Returns
    -------
    w : ndarray (N,)
        Normalised weights (sum 1 to round-off), computed as ``exp(logw − logsumexp(logw))``.
    log_total : float
        ``logsumexp(logw)``; for a bootstrap filter whose previous weights were normalised this
        is the log marginal likelihood of the measurement.

    Raises
    ------
    ValueError
        If ``logw`` contains NaN or +inf (a bug in the likelihood, not a numerical accident).
    lightcurve.errors.ConvergenceError
        If every weight is zero (all −inf): the filter has lost track and must be restarted or
        flagged.
    """
    a = _as_1d_float(logw, "logw")
    if np.any(np.isnan(a)) or np.any(a == np.inf):
        raise ValueError("log weights contain NaN or +inf")
    lse = float(logsumexp_nb(a))
    if lse == -np.inf:
        raise ConvergenceError("all particle weights are zero (every log weight is -inf)")
    w = np.exp(a - lse)
    w /= w.sum()
    return w, lse


def _check_weights(w):
    w = _as_1d_float(w, "weights")
    if not np.all(np.isfinite(w)) or np.any(w < 0.0):
        raise ValueError("weights must be finite and non-negative")
    if not w.sum() > 0.0:
        raise ValueError("weights must not all be zero")
    return w


def effective_sample_size(w) -> float:
    """``N_eff = (Σ wᵢ)² / Σ wᵢ²`` (= 1/Σ wᵢ² for normalised weights)."""
    w = _check_weights(w)
    s = w.sum()
    return float(s * s / np.dot(w, w))


def effective_sample_size_log(logw) -> float:
    """Effective sample size from log weights: ``exp(2 lse(logw) − lse(2 logw))``."""
    a = _as_1d_float(logw, "logw")
    l1 = logsumexp(a)
    if l1 == -np.inf:
        return 0.0
    return float(np.exp(2.0 * l1 - logsumexp(2.0 * a)))


def _chol_parts(R, m):
    R = np.asarray(R, dtype=float)
    if R.ndim == 0:
        R = float(R) * np.eye(m)
    elif R.ndim == 1:
        R = np.diag(R)
    if R.shape != (m, m):
        raise ValueError(f"R must be a scalar, ({m},) diagonal or ({m}, {m}), got {R.shape}")
    try:
        L = np.linalg.cholesky(0.5 * (R + R.T))
    except np.linalg.LinAlgError:
        raise ValueError("measurement covariance R is not positive definite") from None
    Linv = np.ascontiguousarray(np.linalg.inv(L))
    const = -0.5 * m * _LOG_2PI - float(np.sum(np.log(np.diag(L))))
    return Linv, const


def _as_resid(resid):
    r = np.asarray(resid, dtype=np.float64)
    if r.ndim == 1:
        r = r[:, None]
    if r.ndim != 2:
        raise ValueError(f"residuals must have shape (N,) or (N, m), got {r.shape}")
    return np.ascontiguousarray(r)


def gaussian_log_likelihood(resid, R):
    """``log N(rᵢ; 0, R)`` for each row of the residuals ``resid`` (N,) or (N, m) → (N,).

    ``R`` is the measurement-noise covariance (scalar variance, (m,) diagonal or (m, m)), in
    measurement units squared.
    """
    r = _as_resid(resid)
    Linv, const = _chol_parts(R, r.shape[1])
    out = np.zeros(r.shape[0])
    add_gaussian_loglik_nb(out, r, Linv, const)
    return out


def update_log_weights(logw, resid, R):
    """Return ``logw + log N(resid; 0, R)`` (new array; see :func:`gaussian_log_likelihood`).

    Non-finite residuals are refused (ValueError): a filter must skip a NaN measurement before
    weighting, not weight every particle by NaN.
    """
    lw = _as_1d_float(logw, "logw").copy()
    r = _as_resid(resid)
    if r.shape[0] != lw.shape[0]:
        raise ValueError(f"{r.shape[0]} residual rows for {lw.shape[0]} particles")
    if not np.all(np.isfinite(r)):
        raise ValueError("residuals contain NaN or inf")
    Linv, const = _chol_parts(R, r.shape[1])
    add_gaussian_loglik_nb(lw, r, Linv, const)
    return lw


def _n_out(n_out, N):
    n = N if n_out is None else int(n_out)
    if n < 1:
        raise ValueError(f"n_out must be >= 1, got {n}")
    return n


def systematic_resample(w, rng, n_out=None):
    """Systematic resampling → indices (n_out,), non-decreasing.

    Each particle i is copied ``⌊n_out wᵢ⌋`` or ``⌈n_out wᵢ⌉`` times (normalised weights), and
    ``E[count_i] = n_out wᵢ``. ``rng``: Generator or seed; one uniform is drawn.
    """
    w = _check_weights(w)
    n = _n_out(n_out, w.shape[0])
    u0 = float(as_generator(rng).random())
    return systematic_resample_nb(w, u0, n)


def stratified_resample(w, rng, n_out=None):
    """Stratified resampling → indices: one uniform in each stratum ``[j, j+1)/n_out``."""
    w = _check_weights(w)
    n = _n_out(n_out, w.shape[0])
    u = (np.arange(n) + as_generator(rng).random(n)) / n
    return resample_sorted_nb(w, u)


def multinomial_resample(w, rng, n_out=None):
    """Multinomial resampling (Bernard table 6.3) → indices (n_out,), sorted.

    ``n_out`` independent draws from the categorical distribution ``w``; the uniforms are
    drawn from ``rng`` and sorted, then merged with the cumulative weights in O(N).
    """
    w = _check_weights(w)
    n = _n_out(n_out, w.shape[0])
    u = np.sort(as_generator(rng).random(n))
    return resample_sorted_nb(w, u)


RESAMPLING_METHODS = {
    "systematic": systematic_resample,
    "stratified": stratified_resample,
    "multinomial": multinomial_resample,
}


def resample(w, rng, method="systematic", n_out=None):
    """Dispatch to a resampling scheme by name (``systematic``, ``stratified``, ``multinomial``)."""
    try:
        f = RESAMPLING_METHODS[method]
    except KeyError:
        raise ValueError(f"unknown resampling method {method!r}; allowed: "
                         f"{', '.join(RESAMPLING_METHODS)}") from None
    return f(w, rng, n_out)


def _as_cloud(particles):
    x = np.asarray(particles, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] == 0:
        raise ValueError(f"particles must have shape (N, d), got {x.shape}")
    return x


def roughening_sigma(particles, G, d=None):
    """Roughening standard deviations ``σⱼ = 𝒢 Eⱼ N^(−1/d)`` (module docstring) → (d_state,).

    Parameters
    ----------
    particles : (N, d_state) cloud, in the units of each component.
    G : float ≥ 0, the tuning constant 𝒢.
    d : int, optional
        Dimension in the exponent; defaults to ``d_state`` (pass the dimension of the part of
        the state being roughened when it differs).
    """
    x = _as_cloud(particles)
    G = float(G)
    if not (G >= 0.0 and np.isfinite(G)):
        raise ValueError(f"roughening constant G must be finite and >= 0, got {G}")
    dd = x.shape[1] if d is None else int(d)
    if dd < 1:
        raise ValueError(f"dimension d must be >= 1, got {dd}")
    E = np.empty(x.shape[1])
    core.column_ranges(np.ascontiguousarray(x), E)
    return core.roughening_sigma_nb(E, G, x.shape[0], dd)


def roughen(particles, rng, G, d=None):
    """Add roughening jitter to a resampled cloud → ``(new_particles, sigma)``.

    ``new = particles + σ ⊙ z`` with ``z`` standard normal (N, d) drawn from ``rng``
    (Generator or seed) and σ from :func:`roughening_sigma`. The input is not modified.
    """
    x = _as_cloud(particles)
    sig = roughening_sigma(x, G, d)
    z = as_generator(rng).standard_normal(x.shape)
    out = x + z * sig[None, :]
    if np.ndim(particles) == 1:
        out = out[:, 0]
    return out, sig


def weighted_mean_cov(particles, w, unbiased=False):
    """Weighted mean and covariance of a cloud.

    ``x̄ = Σ wᵢ xᵢ``, ``P = Σ wᵢ (xᵢ − x̄)(xᵢ − x̄)ᵀ`` for normalised weights (the sample
    moments of Bernard eq. 7.100–7.105, in whatever representation the caller passes).
    With ``unbiased=True`` P is divided by ``1 − Σ wᵢ²`` (reliability-weights correction,
    equal to the N−1 rule for uniform weights).

    Returns ``mean`` (d,) and ``cov`` (d, d), symmetrised.
    """
    x = _as_cloud(particles)
    w = _check_weights(w)
    if w.shape[0] != x.shape[0]:
        raise ValueError(f"{w.shape[0]} weights for {x.shape[0]} particles")
    w = w / w.sum()
    mean = w @ x
    D = x - mean
    C = (D * w[:, None]).T @ D
    if unbiased:
        v = 1.0 - float(w @ w)
        if not v > 0.0:
            raise ValueError("unbiased covariance needs more than one particle with weight")
        C = C / v
    return mean, 0.5 * (C + C.T)
