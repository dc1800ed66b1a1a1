"""Filter-consistency statistics: NEES, NIS, NMEE, chi-square bounds, NIS divergence detection.

Definitions (Bar-Shalom, Li & Kirubarajan 2001 §5.4.2; O'Keefe 2015 eq. 5.1–5.11):

* NEES   ``εₖ = x̃ₖᵀ Pₖ⁻¹ x̃ₖ``, ``x̃ = x_true − x̂`` (n states) — χ²ₙ for a consistent filter.
* NIS    ``εᵥ,ₖ = νₖᵀ Sₖ⁻¹ νₖ`` (m measurements) — χ²ₘ.
* Averaged over N independent Monte Carlo runs, ``N ε̄ₖ ~ χ²_{N n}`` (NEES) or ``χ²_{N m}``
  (NIS); the two-sided acceptance interval with probability 1 − α is
  ``[χ²_{Nn}(α/2)/N, χ²_{Nn}(1 − α/2)/N]`` (:func:`chi2_interval`).
* The same interval with N replaced by a window length K applies to the time average of one
  run's NIS over K steps (sliding-window detector, O'Keefe §5.1 fault detection).
* NMEE (normalised mean estimation error), per component j:
  ``μⱼ,ₖ = (1/N) Σᵢ x̃ⱼ,ₖⁱ / √(Pⱼⱼ,ₖⁱ)`` ~ N(0, 1/N); interval ``±z_{1−α/2}/√N``.

Array conventions: the last axis holds the vector components (n or m) and the last two the
matrix; leading axes (runs, epochs, …) broadcast. Functions that average over Monte Carlo
runs take the runs on axis 0.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy import stats

__all__ = [
    "normalized_squared",
    "nees",
    "nis",
    "chi2_interval",
    "correlated_average_upper",
    "averaged_nees",
    "averaged_nis",
    "nmee",
    "nmee_interval",
    "ConsistencyResult",
    "chi2_consistency",
    "windowed_average",
    "NISDivergenceDetector",
]


def normalized_squared(e, C):
    """``eᵀ C⁻¹ e`` over stacked vectors ``e`` (..., n) and covariances ``C`` (..., n, n).

    Computed with a Cholesky factor (``|L⁻¹ e|²``). When ``C`` has the same shape as ``e`` the
    entries are scalar statistics with variances ``C`` and ``e²/C`` is returned element-wise.
    Raises ValueError when a covariance is not positive definite (consistency statistics are
    undefined there; the filter must have flagged that step).
    """
    e = np.asarray(e, dtype=float)
    C = np.asarray(C, dtype=float)
    if C.shape == e.shape:
        # scalar statistics: element-wise variances
        if np.any(~(C > 0.0)):
            raise ValueError("a variance is not positive; NEES/NIS undefined")
        return e * e / C
    n = e.shape[-1]
    if C.shape[-2:] != (n, n):
        raise ValueError(f"covariance shape {C.shape} does not match vectors {e.shape}")
    C = 0.5 * (C + np.swapaxes(C, -1, -2))
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        raise ValueError("a covariance is not positive definite; NEES/NIS undefined") from None
    shape = np.broadcast_shapes(e.shape[:-1], C.shape[:-2])
    eb = np.broadcast_to(e, shape + (n,))
    Lb = np.broadcast_to(L, shape + (n, n))
    z = np.linalg.solve(Lb, eb[..., None])[..., 0]
    return np.sum(z * z, axis=-1)


def nees(err, P):
    """Normalised estimation error squared ``x̃ᵀ P⁻¹ x̃`` (…,) from errors (…, n), P (…, n, n)."""
    return normalized_squared(err, P)


def nis(nu, S):
    """Normalised innovation squared ``νᵀ S⁻¹ ν`` (…,) from innovations (…, m), S (…, m, m)."""
    return normalized_squared(nu, S)


def _check_prob(prob):
    prob = float(prob)
    if not 0.0 < prob < 1.0:
        raise ValueError(f"probability must lie in (0, 1), got {prob}")
    return prob


def chi2_interval(dof, prob=0.95, n_avg=1):
    """Two-sided acceptance interval of the average of ``n_avg`` independent χ²_dof variables.

    Returns ``(lo, hi) = (χ²_{n_avg·dof}((1−prob)/2), χ²_{n_avg·dof}((1+prob)/2)) / n_avg``
    (Bar-Shalom et al. 2001 §5.4.2; O'Keefe 2015 eq. 5.1–5.11). ``n_avg`` is the number
    of Monte Carlo runs (ensemble average) or the window length (time average).
    """
    dof = int(dof)
    n_avg = int(n_avg)
    if dof < 1 or n_avg < 1:
        raise ValueError(f"dof and n_avg must be >= 1, got dof={dof}, n_avg={n_avg}")
    prob = _check_prob(prob)
    a = 0.5 * (1.0 - prob)
    k = dof * n_avg
    return float(stats.chi2.ppf(a, k) / n_avg), float(stats.chi2.ppf(1.0 - a, k) / n_avg)


def correlated_average_upper(prob, n_avg, share):
    """Upper bound of the two-sided ``prob`` interval of the average of ``n_avg`` scalar
    NIS values when a share ``share`` (0-1, array-like) of each innovation variance is an
    error that stays constant over the window (an error correlated over longer than the
    window, e.g. a coarse albedo grid's representation error).

    With normalised innovations ``z = √f e + √(1−f) w`` (e, w standard normal, e the same
    for the whole window, w white), the average ε̄ of z² has mean 1 and variance
    ``2 (f² + (1 − f²)/K)``; it is matched by a scaled χ²_ν/ν with the same two moments
    (Satterthwaite 1946, Biometrics Bull. 2(6):110-114), ``ν = 1/(f² + (1 − f²)/K)``.
    ``f = 0`` gives ν = K, the independent-sample bound of :func:`chi2_interval`;
    ``f = 1`` gives ν = 1 (one χ²₁ value, whatever the window).
    """
    n_avg = int(n_avg)
    if n_avg < 1:
        raise ValueError(f"n_avg must be >= 1, got {n_avg}")
    prob = _check_prob(prob)
    f = np.clip(np.asarray(share, dtype=float), 0.0, 1.0)
    nu = 1.0 / (f * f + (1.0 - f * f) / n_avg)
    return stats.chi2.ppf(0.5 * (1.0 + prob), nu) / nu


def order_statistic_interval(dof, k, n, prob=0.99):
    """Two-sided interval of the k-th smallest of ``n`` independent χ²_dof variables.

    Exact: ``F(X_(k)) ~ Beta(k, n − k + 1)`` for the order statistic of any continuous
    distribution F (David & Nagaraja 2003, Order Statistics, 3rd ed., §2.1), so
    ``(lo, hi) = F⁻¹(Beta⁻¹((1 ∓ prob)/2))`` with F the χ²_dof distribution. With
    ``k = ⌈n/2⌉`` it bounds the (lower) median, a statistic a few gross outliers cannot move.
    """
    dof, k, n = int(dof), int(k), int(n)
    if dof < 1 or n < 1 or not 1 <= k <= n:
        raise ValueError(f"need dof >= 1 and 1 <= k <= n, got dof={dof}, k={k}, n={n}")
    prob = _check_prob(prob)
    a = 0.5 * (1.0 - prob)
    lo_u, hi_u = stats.beta.ppf([a, 1.0 - a], k, n - k + 1)
    return float(stats.chi2.ppf(lo_u, dof)), float(stats.chi2.ppf(hi_u, dof))


def averaged_nees(errs, P):
    """Ensemble-averaged NEES over Monte Carlo runs (axis 0): errs (N, …, n), P (N, …, n, n)."""
    return np.mean(nees(errs, P), axis=0)


def averaged_nis(nus, S):
    """Ensemble-averaged NIS over Monte Carlo runs (axis 0): nus (N, …, m), S (N, …, m, m)."""
    return np.mean(nis(nus, S), axis=0)


def nmee(errs, P):
    """Normalised mean estimation error per component, averaged over runs (axis 0).

    Parameters
    ----------
    errs : (N, …, n) estimation errors ``x_true − x̂``.
    P : (N, …, n, n) covariances, or (N, …, n) standard deviations.

    Returns
    -------
    ndarray (…, n): ``(1/N) Σᵢ x̃ⱼⁱ / σⱼⁱ``.
    """
    e = np.asarray(errs, dtype=float)
    P = np.asarray(P, dtype=float)
    if P.shape == e.shape:
        sig = P
    elif P.shape == e.shape + (e.shape[-1],):
        sig = np.sqrt(np.diagonal(P, axis1=-2, axis2=-1))
    else:
        raise ValueError(f"P shape {P.shape} matches neither errors {e.shape} nor their "
                         "covariances")
    if np.any(~(sig > 0.0)):
        raise ValueError("standard deviations must be > 0 for the NMEE")
    return np.mean(e / sig, axis=0)


def nmee_interval(n_runs, prob=0.95):
    """``(−z, +z)`` with ``z = Φ⁻¹((1+prob)/2)/√N``: acceptance band of each NMEE component."""
    n_runs = int(n_runs)
    if n_runs < 1:
        raise ValueError(f"n_runs must be >= 1, got {n_runs}")
    z = float(stats.norm.ppf(0.5 * (1.0 + _check_prob(prob))) / np.sqrt(n_runs))
    return -z, z


@dataclass(frozen=True)
class ConsistencyResult:
    """Outcome of :func:`chi2_consistency`.

    Attributes
    ----------
    values : ndarray — the averaged statistic per epoch.
    lo, hi : float — acceptance interval.
    fraction_inside : float — share of finite epochs with ``lo ≤ value ≤ hi``.
    dof, n_avg : int; prob : float — parameters of the interval.
    """

    values: np.ndarray
    lo: float
    hi: float
    fraction_inside: float
    dof: int
    n_avg: int
    prob: float

    @property
    def consistent(self) -> bool:
        """True when at least ``prob`` of the epochs lie inside the interval."""
        return self.fraction_inside >= self.prob


def chi2_consistency(values, dof, n_avg, prob=0.95):
    """Compare averaged NEES/NIS ``values`` with their two-sided χ² interval.

    ``values`` are averages over ``n_avg`` runs (or a window of ``n_avg`` steps) of a statistic
    with ``dof`` degrees of freedom. NaN entries (skipped epochs) are ignored.
    """
    v = np.asarray(values, dtype=float)
    lo, hi = chi2_interval(dof, prob, n_avg)
    fin = v[np.isfinite(v)]
    frac = float(np.mean((fin >= lo) & (fin <= hi))) if fin.size else float("nan")
    return ConsistencyResult(values=v, lo=lo, hi=hi, fraction_inside=frac, dof=int(dof),
                             n_avg=int(n_avg), prob=float(prob))


def windowed_average(values, window):
    """Trailing average of the last ``window`` *finite* values at each index (the averaged
    NIS of O'Keefe 2015 eq. 5.11 over a running window of samples, §5.1).

    NaN marks a step without a statistic (no measurement, refused update) and is skipped, so
    each average is over up to ``window`` valid values. Returns ``(avg, count)``, both (T,);
    ``avg`` is NaN where ``count`` is 0.
    """
    v = np.asarray(values, dtype=float).ravel()
    window = int(window)
    if window < 1:
        raise ValueError(f"window must be >= 1, got {window}")
    ok = np.isfinite(v)
    cnt = np.cumsum(ok)  # number of valid values up to and including t
    cum_valid = np.concatenate([[0.0], np.cumsum(v[ok])])
    j0 = np.maximum(cnt - window, 0)
    count = cnt - j0
    avg = np.full(v.shape, np.nan)
    has = count > 0
    avg[has] = (cum_valid[cnt[has]] - cum_valid[j0[has]]) / count[has]
    return avg, count


class NISDivergenceDetector:
    """Sliding-window NIS test for divergence or sensor faults (O'Keefe §5.1).

    Keeps the last ``window`` finite NIS values of one filter (or one sensor's scalar
    innovations). Once the window is full, the step is *flagged* when the window average
    exceeds the upper bound of the two-sided ``prob`` χ² interval for ``window`` samples of
    ``dof`` degrees of freedom (so the false-alarm probability of one full-window test on a
    consistent filter is ``(1 − prob)/2``). Averages below the lower bound are reported by
    :attr:`too_small` (over-pessimistic filter), not flagged.

    Parameters
    ----------
    dof : int — measurement dimension m of each NIS value.
    window : int — number of valid steps averaged (K).
    prob : float — probability of the two-sided interval (default 0.99).
    """

    def __init__(self, dof, window, prob=0.99):
        self.dof = int(dof)
        self.window = int(window)
        self.prob = float(prob)
        self.lo, self.hi = chi2_interval(self.dof, self.prob, self.window)
        self._buf = deque(maxlen=self.window)
        self._sum = 0.0
        self.average = float("nan")
        self.too_small = False

    def reset(self):
        """Forget all stored values."""
        self._buf.clear()
        self._sum = 0.0
        self.average = float("nan")
        self.too_small = False

    def update(self, value) -> bool:
        """Add one NIS value (NaN = no measurement, ignored); return True when flagged."""
        value = float(value)
        if np.isfinite(value):
            if value < 0.0:
                raise ValueError(f"NIS values are non-negative, got {value}")
            self._buf.append(value)
            # recompute instead of running sums: exact, and the window is short
            self._sum = float(np.sum(np.fromiter(self._buf, dtype=float)))
        if len(self._buf) < self.window:
            self.average = self._sum / len(self._buf) if self._buf else float("nan")
            self.too_small = False
            return False
        self.average = self._sum / self.window
        self.too_small = self.average < self.lo
        return self.average > self.hi

    def run(self, values):
        """Apply the detector to a whole sequence → boolean flags (T,). Resets first."""
        self.reset()
        return np.array([self.update(v) for v in np.asarray(values, dtype=float).ravel()],
                        dtype=bool)

    @staticmethod
    def first_flag(flags):
        """Index of the first True in ``flags``, or None."""
        idx = np.flatnonzero(np.asarray(flags, dtype=bool))
        return int(idx[0]) if idx.size else None
