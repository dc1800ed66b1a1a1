"""Particle-filter kernels on plain float arrays: weights, ESS, resampling, roughening, moves.

Every equation of the particle machinery exists here once; the bootstrap attitude filter
(:mod:`lightcurve.filters.bpf`) and the checked object layer :mod:`lightcurve.estimation.particles`
call these kernels.

* Log weights with log-sum-exp (Bernard 2021 eq. 6.56–6.57 in log form): ``log w_i += φ ℓ_i``
  then ``log w_i −= log Σ exp(log w_j)``; ``ℓ_i = −½ ((y − m_i)/σ)²`` is the Gaussian
  log-likelihood of one scalar measurement without its constant (the constant cancels in the
  normalisation); ``ℓ_i = −inf`` where the prediction ``m_i`` is not finite.
* Effective sample size (eq. 6.61): ``N_eff = 1/Σ w_i² = (Σ e^{a_i})² / Σ e^{2 a_i}``.
* Resampling into caller-owned index arrays: systematic (Kitagawa 1996; positions
  ``(u₀ + j)/N``) and multinomial (Bernard table 6.3: N independent uniforms, here sorted and
  merged with the cumulative weights, which returns the particles table 6.3 returns, in sorted
  order).
* Roughening (Bernard eq. 6.63 / 7.106, tables 6.6 and 7.9): ``σ_l = 𝒢 E_l N^(−1/n)`` with
  ``E_l`` the range (max − min) of component l over the cloud and n the state dimension.
* Liu & West (2001) shrinkage kernel: ``x_i ← a x_i + (1 − a) x̄ + h L ε_i`` with
  ``L Lᵀ`` the cloud covariance.
* Counter-based random numbers (Philox4x32-10, Salmon et al. 2011, "Parallel random numbers:
  as easy as 1, 2, 3", SC'11) with ziggurat normals (Marsaglia & Tsang 2000, Doornik 2005):
  normal draw j of row i of call c is a pure function of ``(key, i, j, c)``, so the draws do not depend on the number of threads, the chunking, or the
  device (the same function runs in the CUDA kernels of :mod:`lightcurve.filters.bpf_gpu`).

Parallel reductions use a fixed number of chunks that depends on N only (:func:`n_chunks`), and
sum the chunk partials in order: the results are the same for any thread count.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .specialise import jit_copy

__all__ = [
    "n_chunks", "chunk_bounds", "chunk_sums", "chunked_sum_kernel", "max_finite", "logsumexp_nb", "normalize_log_weights_nb", "add_loglik_normalize",
    "exp_or_zero", "ess_tempered", "temper_exponent", "temper_exponent_bracketed",
    "innovation_loglik", "gaussian_loglik", "gaussian_loglik_into",
    "cumulative_weights",
    "systematic_resample_into", "sorted_resample_into", "gather_rows", "column_ranges",
    "roughening_sigma_nb", "mean_cov_rows", "weighted_mean_cov_rows", "liu_west_rows",
    "philox4x32", "philox_normals", "philox_normals_into", "philox_uniforms", "ziggurat_normal",
]

_CHUNK = 2048      # particles per reduction chunk (fixed: results independent of threads)
_MAX_CHUNKS = 512


@nb.njit(cache=True, inline="always")
def n_chunks(N):
    """Number of work chunks for N items: ``ceil(N / 2048)`` capped at 512 (≥ 1).

    Depends on N only, so chunked reductions give the same sums on any thread count.
    """
    c = (N + _CHUNK - 1) // _CHUNK
    if c < 1:
        c = 1
    if c > _MAX_CHUNKS:
        c = _MAX_CHUNKS
    return c


@nb.njit(cache=True, inline="always")
def chunk_bounds(c, N, nch):
    """Items ``lo:hi`` of chunk ``c`` of ``nch`` (:func:`n_chunks`) over N items."""
    return c * N // nch, (c + 1) * N // nch


@nb.njit(cache=True)
def chunk_sums(part):
    """Column sums (K,) of the per-chunk partials ``part`` (nch, K), added in chunk order: the
    combining step of every chunked reduction (the same sums on any thread count). Not
    inlined: inside a ``parallel=True`` caller its ``np.zeros`` would become one more
    parallel region per call (measured 8-10 % of the tempered filter at 2 threads)."""
    K = part.shape[1]
    out = np.zeros(K)
    for c in range(part.shape[0]):
        for k in range(K):
            out[k] += part[c, k]
    return out


def _chunk_acc(lo, hi, *args):
    acc = _ZERO  # noqa: F821  (_ZERO, _item, _K, _chunk bound per copy)
    for i in range(lo, hi):
        acc = _item(i, acc, args)  # noqa: F821
    return acc


def _chunked_sums(*args):
    N = args[0].shape[0]
    nch = n_chunks(N)
    part = np.zeros((nch, _K))  # noqa: F821
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        acc = _chunk(lo, hi, *args)  # noqa: F821
        for k in range(_K):  # noqa: F821
            part[c, k] = acc[k]
    return chunk_sums(part)


def chunked_sum_kernel(item, K):
    """The parallel kernel ``name(*args)`` of ``item`` (named ``name_item``): the (K,) sums over
    ``i < len(args[0])`` of the contributions of ``item(i, acc, args)``, an
    ``inline="always"`` kernel that returns ``acc`` (a K-tuple of running sums) with row i's
    terms added and may write row i of an argument.

    Each of :func:`n_chunks` fixed chunks (:func:`chunk_bounds`) sums its rows in order from
    zero (``name_chunk``, serial: the item is inlined there, and the arrays it takes out of
    ``args`` are not inside a ``prange`` body, where numba can lose writes to an array taken
    out of a tuple); the chunks run in ``prange`` and :func:`chunk_sums` adds their partials in
    order: the same sums on any thread count. Compiled copies of the two loops per ``item``
    (:func:`~lightcurve.core.specialise.jit_copy`: direct calls, not function pointers).
    """
    name = item.__name__.removesuffix("_item")
    zero = (0.0,) * K
    chunk = jit_copy(_chunk_acc, name + "_chunk", f"Serial sums of :func:`{item.__name__}` over "
                     "rows lo:hi.", {"cache": True}, _item=item, _ZERO=zero)
    doc = f"Ordered chunked sums (K = {K}) over rows i of :func:`{item.__name__}`: {item.__doc__}"
    return jit_copy(_chunked_sums, name, doc, {"cache": True, "parallel": True}, _chunk=chunk,
                    _K=K)


_EXP_ZERO = -746.0   # below ln(2⁻¹⁰⁷⁵) = −745.133…: exp rounds to 0 (half the least subnormal)


@nb.njit(cache=True, inline="always")
def exp_or_zero(x):
    """``math.exp(x)`` for every double x (NaN included), returning the 0 that exp rounds to
    below −746 without calling it: the libm underflow path costs ≈ 3× a normal exp, and the
    tempering evaluates it for most particles (weights ≪ 2⁻¹⁰⁷⁴ under the full likelihood)."""
    return 0.0 if x < _EXP_ZERO else math.exp(x)


# --------------------------------------------------------------------------------------------
# log weights, ESS
# --------------------------------------------------------------------------------------------

@nb.njit(cache=True, parallel=True)
def _max_tempered(logw, ll, phi):
    """max_i (logw_i + φ ll_i) (φ = 0: max logw); −inf for an empty or all −inf array."""
    N = logw.shape[0]
    nch = n_chunks(N)
    part = np.full(nch, -np.inf)
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        m = -np.inf
        for i in range(lo, hi):
            a = logw[i] + phi * ll[i] if phi != 0.0 else logw[i]
            if a > m:
                m = a
        part[c] = m
    m = -np.inf
    for c in range(nch):
        if part[c] > m:
            m = part[c]
    return m


@nb.njit(cache=True)
def max_finite(a):
    """Largest entry of a 1-D array (−inf if empty or every entry is −inf; NaN ignored)."""
    return _max_tempered(a, a, 0.0)


@nb.njit(cache=True)
def logsumexp_nb(a):
    """``log Σ exp(a_i)`` of a 1-D float64 array, stable for very negative entries.

    Returns −inf when every entry is −inf (or the array is empty); NaN when an entry is NaN;
    +inf when an entry is +inf.
    """
    n = a.shape[0]
    m = -np.inf
    for i in range(n):
        if np.isnan(a[i]):
            return np.nan
        if a[i] > m:
            m = a[i]
    if m == -np.inf:
        return -np.inf
    if m == np.inf:
        return np.inf
    s = 0.0
    for i in range(n):
        s += math.exp(a[i] - m)
    return m + math.log(s)


@nb.njit(cache=True, inline="always")
def _sum_exp_item(i, acc, args):
    """``(e^{a−m}, e^{2(a−m)})`` of row i, ``a = logw + φ ll`` (0 where a = −inf)."""
    logw, ll, phi, m = args
    a = logw[i] + phi * ll[i] if phi != 0.0 else logw[i]
    if a > -np.inf:
        e = exp_or_zero(a - m)
        return acc[0] + e, acc[1] + e * e
    return acc


_sum_exp = chunked_sum_kernel(_sum_exp_item, 2)


@nb.njit(cache=True)
def ess_tempered(logw, ll, phi):
    """Effective sample size of the weights ``exp(logw + φ ll)`` (unnormalised logs).

    ``N_eff = (Σ e^{a−m})² / Σ e^{2(a−m)}`` (Bernard eq. 6.61) with ``a = logw + φ ll``,
    m = max a (φ = 0 ignores ``ll``; −inf entries count as zero weight). Returns 0 when every
    weight is zero. No temporary arrays of size N.
    """
    m = _max_tempered(logw, ll, phi)
    if m == -np.inf or np.isnan(m):
        return 0.0
    tot = _sum_exp(logw, ll, phi, m)
    s1, s2 = tot[0], tot[1]
    return s1 * s1 / s2


@nb.njit(cache=True)
def temper_exponent(logw, ll, rest, target, steps):
    """Largest φ ∈ (0, rest] with ``N_eff(logw + φ ll) ≥ target`` by bisection (``steps``
    halvings of [0, rest]; the progressive correction of Oudjane & Musso 2000). Returns the
    lower end of the final bracket (0 when even tiny φ falls below the target).

    Each N_eff evaluation is one pass: the exponentials are shifted by the bound
    ``max logw + φ max ll ≥ max (logw + φ ll)`` (exact once the weights are uniform), with
    the exact two-pass :func:`ess_tempered` when that shift would underflow every weight.
    """
    mw = _max_tempered(logw, ll, 0.0)
    ml = _max_tempered(ll, ll, 0.0)
    lo = 0.0
    hi = rest
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        e = 0.0
        if mw > -np.inf and ml > -np.inf:
            tot = _sum_exp(logw, ll, mid, mw + mid * ml)
            s1, s2 = tot[0], tot[1]
            if s1 > 1e-150 and s2 > 0.0:
                e = s1 * s1 / s2
            else:
                e = ess_tempered(logw, ll, mid)
        if e >= target:
            lo = mid
        else:
            hi = mid
    return lo


@nb.njit(cache=True)
def _ess_shifted(logw, ll, phi, mw, ml):
    """N_eff of ``logw + φ ll`` in one pass with the shift bound of :func:`temper_exponent`
    (``mw``, ``ml`` the maxima of logw and ll); the exact two-pass value when the shift
    underflows every weight."""
    if not (mw > -np.inf and ml > -np.inf):
        return 0.0
    tot = _sum_exp(logw, ll, phi, mw + phi * ml)
    s1, s2 = tot[0], tot[1]
    if s1 > 1e-150 and s2 > 0.0:
        return s1 * s1 / s2
    return ess_tempered(logw, ll, phi)


@nb.njit(cache=True)
def temper_exponent_bracketed(logw, ll, rest, target, rtol, max_evals):
    """Largest φ ∈ (0, rest] with ``N_eff(logw + φ ll) ≥ target`` (the progressive correction
    of Oudjane & Musso 2000) to the relative precision ``rtol`` in fewer N_eff evaluations than
    the 24 halvings of :func:`temper_exponent`: a bisection over the binary exponent of φ/rest
    (2⁰ … 2⁻⁴⁰, N_eff(rest) < target assumed, as the caller has checked) finds the octave of
    the root, then regula falsi with the Illinois modification (Dowell & Jarratt 1971, BIT 11)
    on ``log N_eff − log target`` narrows it to ``hi − lo ≤ rtol · lo``. Returns the lower end
    of the final bracket (N_eff ≥ target there), 0 when even rest·2⁻⁴⁰ falls below, and stops
    after ``max_evals`` evaluations. Typically 9–12 evaluations; the φ differs from the
    bisection's within its bracket, so runs differ from those of :func:`temper_exponent`."""
    mw = _max_tempered(logw, ll, 0.0)
    ml = _max_tempered(ll, ll, 0.0)
    kf = 0            # N_eff(rest · 2^-kf) < target
    ko = 41           # N_eff(rest · 2^-ko) ≥ target (41: not found yet)
    elo = 0.0
    ehi = -1.0        # not evaluated
    evals = 0
    while ko - kf > 1 and evals < max_evals:
        km = (kf + ko) // 2
        e = _ess_shifted(logw, ll, rest * 2.0 ** (-km), mw, ml)
        evals += 1
        if e >= target:
            ko = km
            elo = e
        else:
            kf = km
            ehi = e
    if ko > 40:
        return 0.0
    lo = rest * 2.0 ** (-ko)
    hi = rest * 2.0 ** (-kf)
    if ehi < 0.0:
        ehi = _ess_shifted(logw, ll, hi, mw, ml)
        evals += 1
    flo = math.log(elo / target) if elo > 0.0 else 0.0
    fhi = math.log(ehi / target) if ehi > 0.0 else -np.inf
    side = 0
    while hi - lo > rtol * lo and evals < max_evals:
        x = 0.5 * (lo + hi)
        if fhi > -np.inf and flo - fhi > 0.0:
            xs = lo + (hi - lo) * flo / (flo - fhi)
            if lo < xs < hi:
                x = xs
        e = _ess_shifted(logw, ll, x, mw, ml)
        evals += 1
        fx = math.log(e / target) if e > 0.0 else -np.inf
        if e >= target:
            lo = x
            flo = fx
            if side == 1:
                fhi *= 0.5
            side = 1
        else:
            hi = x
            fhi = fx
            if side == -1:
                flo *= 0.5
            side = -1
    return lo


@nb.njit(cache=True, inline="always")
def _exp_shifted_item(i, acc, args):
    """Writes ``w_i = exp(logw_i − mx)`` and adds it."""
    logw, mx, w = args
    e = exp_or_zero(logw[i] - mx)
    w[i] = e
    return (acc[0] + e,)


@nb.njit(cache=True, inline="always")
def _finish_normalize_item(i, acc, args):
    """``logw_i −= lse``, ``w_i /= s``; adds ``w_i²``."""
    logw, w, lse, s = args
    logw[i] -= lse
    w[i] /= s
    return (acc[0] + w[i] * w[i],)


_exp_shifted = chunked_sum_kernel(_exp_shifted_item, 1)
_finish_normalize = chunked_sum_kernel(_finish_normalize_item, 1)


@nb.njit(cache=True, parallel=True)
def _add_scaled(logw, ll, phi):
    N = logw.shape[0]
    for i in nb.prange(N):
        logw[i] += phi * ll[i]


@nb.njit(cache=True)
def add_loglik_normalize(logw, ll, phi, w):
    """In place ``logw ← logw + φ ll`` then normalise with log-sum-exp; fills ``w = exp(logw)``.

    Bernard eq. 6.56–6.57 in log form (φ = 1: the full likelihood; φ < 1: one stage of the
    progressive correction; φ = 0 only normalises). Returns ``(N_eff, ok)`` with
    ``N_eff = 1/Σ w²`` (eq. 6.61); ``ok`` False (logw after the addition, w untouched) when
    every weight is zero.
    """
    if phi != 0.0:
        _add_scaled(logw, ll, phi)
    mx = _max_tempered(logw, ll, 0.0)
    if not mx > -np.inf:
        return 0.0, False
    s = _exp_shifted(logw, mx, w)[0]
    lse = mx + math.log(s)
    s2 = _finish_normalize(logw, w, lse, s)[0]
    return 1.0 / s2, True


@nb.njit(cache=True)
def normalize_log_weights_nb(logw, w):
    """Normalise ``logw`` in place (log-sum-exp) and fill ``w``; returns ``(log Σ e^{logw}, ok)``
    (the log total before normalising; ``ok`` False when every weight is zero)."""
    mx = _max_tempered(logw, logw, 0.0)
    if not mx > -np.inf:
        return -np.inf, False
    s = _exp_shifted(logw, mx, w)[0]
    lse = mx + math.log(s)
    _finish_normalize(logw, w, lse, s)
    return lse, True


@nb.njit(cache=True, inline="always")
def _innov_pass1_item(i, acc, args):
    """Writes ``ll_i`` (:func:`innovation_loglik`); adds the prior weight ``e`` and ``e m_i`` of a
    finite prediction."""
    logw, mpred, y, sig, ll, mx = args
    m = mpred[i]
    ll[i] = gaussian_loglik(y, m, sig)
    if np.isfinite(m):
        e = exp_or_zero(logw[i] - mx) if mx > -np.inf else 1.0
        return acc[0] + e, acc[1] + e * m
    return acc


@nb.njit(cache=True, inline="always")
def gaussian_loglik(y, m, sig):
    """``−½ ((y − m)/σ)²`` (Bernard eq. 6.55–6.56 without the constant); −inf where the
    prediction ``m`` is not finite (the particle reflects no light)."""
    if np.isfinite(m):
        r = (y - m) / sig
        return -0.5 * r * r
    return -np.inf


@nb.njit(cache=True, inline="always")
def _innov_pass2_item(i, acc, args):
    """Adds ``e (m_i − mean)²`` of a finite prediction."""
    logw, mpred, mean, mx = args
    m = mpred[i]
    if np.isfinite(m):
        e = exp_or_zero(logw[i] - mx) if mx > -np.inf else 1.0
        return (acc[0] + e * (m - mean) * (m - mean),)
    return acc


_innov_pass1 = chunked_sum_kernel(_innov_pass1_item, 2)
_innov_pass2 = chunked_sum_kernel(_innov_pass2_item, 1)


@nb.njit(cache=True)
def innovation_loglik(logw, mpred, y, sig, ll):
    """Per-particle log-likelihoods and the prior-weighted predictive moments of one scalar
    measurement.

    Fills ``ll[i] = −½ ((y − m_i)/σ)²`` (Bernard eq. 6.55–6.56 without the constant; −inf where
    ``m_i`` is not finite: the particle reflects no light). Returns ``(ŷ, var_m, ok)``: mean
    and variance of the finite predictions under the prior weights ``exp(logw)``
    (renormalised over them); ``ok`` False when no prediction is finite. Magnitudes, mag².
    """
    mx = _max_tempered(logw, logw, 0.0)
    tot = _innov_pass1(logw, mpred, y, sig, ll, mx)
    s0, s1 = tot[0], tot[1]
    if not s0 > 0.0:
        return np.nan, np.nan, False
    mean = s1 / s0
    s2 = _innov_pass2(logw, mpred, mean, mx)[0]
    return mean, s2 / s0, True


@nb.njit(cache=True, parallel=True)
def gaussian_loglik_into(mpred, y, sig, ll):
    """``ll[i] = −½ ((y − m_i)/σ)²``, −inf where ``m_i`` is not finite: the log-likelihoods of
    :func:`innovation_loglik` (same arithmetic, the same values) without its predictive
    moments, for a caller that already has them (a new σ, a re-predicted cloud)."""
    N = mpred.shape[0]
    for i in nb.prange(N):
        ll[i] = gaussian_loglik(y, mpred[i], sig)


# --------------------------------------------------------------------------------------------
# resampling
# --------------------------------------------------------------------------------------------

@nb.njit(cache=True)
def cumulative_weights(w, C):
    """Running sums ``C_i = Σ_{j≤i} w_j`` (serial, in order) → ``(total, last)``: the total and
    the index of the last positive weight (−1 when none)."""
    N = w.shape[0]
    c = 0.0
    last = -1
    for i in range(N):
        c += w[i]
        C[i] = c
        if w[i] > 0.0:
            last = i
    return c, last


@nb.njit(cache=True, inline="always")
def _first_above(C, last, u):
    """Smallest i with ``u < C_i``, capped at ``last`` (binary search; C non-decreasing)."""
    lo = 0
    hi = last
    while lo < hi:
        mid = (lo + hi) // 2
        if u < C[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@nb.njit(cache=True, parallel=True)
def _merge_sorted(C, total, last, u0, u, systematic, idx):
    """Indices for sorted positions against the cumulative weights, chunked in parallel.

    Position j is ``(u0 + j)/n · total`` (systematic) or ``u[j] · total`` (sorted uniforms);
    it selects the smallest i with position < C_i (capped at the last positive weight). Each
    chunk finds its first index by binary search and merges from there, which gives the
    indices of one serial merge.
    """
    n = idx.shape[0]
    nch = n_chunks(n)
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, n, nch)
        if lo >= hi:
            continue
        p = (u0 + lo) / n * total if systematic else u[lo] * total
        i = _first_above(C, last, p)
        for j in range(lo, hi):
            p = (u0 + j) / n * total if systematic else u[j] * total
            while p >= C[i] and i < last:
                i += 1
            idx[j] = i


@nb.njit(cache=True)
def systematic_resample_into(w, u0, C, idx):
    """Systematic resampling: ``idx[j]`` (j < len(idx)) picks particle i when
    ``C_{i−1} ≤ (u₀ + j)/n · Σw < C_i`` (Kitagawa 1996), u₀ ∈ [0, 1) the single uniform.

    ``w`` ≥ 0 need not sum to one; ``C`` (N,) is work space for the cumulative sums. Zero-weight
    particles are never selected; indices are non-decreasing. Returns False (idx untouched)
    when every weight is zero.
    """
    total, last = cumulative_weights(w, C)
    if last < 0:
        return False
    _merge_sorted(C, total, last, u0, C, True, idx)
    return True


@nb.njit(cache=True)
def sorted_resample_into(w, u_sorted, C, idx):
    """Multinomial resampling merge (Bernard table 6.3): ``idx[j]`` is the particle i with
    ``C_{i−1} ≤ u_j Σw < C_i`` for ascending uniforms ``u_sorted`` in [0, 1). Returns False
    when every weight is zero."""
    total, last = cumulative_weights(w, C)
    if last < 0:
        return False
    _merge_sorted(C, total, last, 0.0, u_sorted, False, idx)
    return True


@nb.njit(cache=True, parallel=True)
def gather_rows(src, idx, dst):
    """``dst[j] = src[idx[j]]`` for 2-D float arrays (rows copied in parallel)."""
    n = idx.shape[0]
    D = src.shape[1]
    for j in nb.prange(n):
        k = idx[j]
        for d in range(D):
            dst[j, d] = src[k, d]


# --------------------------------------------------------------------------------------------
# roughening and kernel moves
# --------------------------------------------------------------------------------------------

@nb.njit(cache=True, parallel=True)
def column_ranges(X, E):
    """``E_l = max_i X_il − min_i X_il`` for every column l of X (N, D) (chunked, parallel)."""
    N, D = X.shape
    nch = n_chunks(N)
    mn = np.full((nch, D), np.inf)
    mxs = np.full((nch, D), -np.inf)
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        for i in range(lo, hi):
            for d in range(D):
                v = X[i, d]
                if v < mn[c, d]:
                    mn[c, d] = v
                if v > mxs[c, d]:
                    mxs[c, d] = v
    for d in range(D):
        a = np.inf
        b = -np.inf
        for c in range(nch):
            if mn[c, d] < a:
                a = mn[c, d]
            if mxs[c, d] > b:
                b = mxs[c, d]
        E[d] = b - a


@nb.njit(cache=True)
def roughening_sigma_nb(E, G, N, n):
    """Table 7.9 / eq. 7.106: ``σ_l = 𝒢 E_l N^(−1/n)`` for the ranges ``E`` (D,) of a cloud of N
    particles in an n-dimensional state. Returns a new (D,) array."""
    f = float(N) ** (-1.0 / n)
    out = np.empty(E.shape[0])
    for d in range(E.shape[0]):
        out[d] = G * E[d] * f
    return out


@nb.njit(cache=True, parallel=True)
def _mean_cov_partials(X, w, use_w, mean, P):
    N, D = X.shape
    nch = P.shape[0]
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        x = np.empty(D)
        for i in range(lo, hi):
            wi = w[i] if use_w else 1.0
            for d in range(D):
                x[d] = X[i, d] - mean[d]
            for a in range(D):
                xa = wi * x[a]
                for b in range(a + 1):
                    P[c, a, b] += xa * x[b]


@nb.njit(cache=True, parallel=True)
def _mean_partials(X, w, use_w, M):
    N, D = X.shape
    nch = M.shape[0]
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        for i in range(lo, hi):
            wi = w[i] if use_w else 1.0
            for d in range(D):
                M[c, d] += wi * X[i, d]


@nb.njit(cache=True)
def _mean_cov(X, w, use_w):
    N, D = X.shape
    nch = n_chunks(N)
    M = np.zeros((nch, D))
    _mean_partials(X, w, use_w, M)
    mean = chunk_sums(M)
    if not use_w:
        for d in range(D):
            mean[d] /= N
    P = np.zeros((nch, D, D))
    _mean_cov_partials(X, w, use_w, mean, P)
    C = np.zeros((D, D))
    for c in range(nch):
        for a in range(D):
            for b in range(a + 1):
                C[a, b] += P[c, a, b]
    for a in range(D):
        for b in range(a + 1):
            if not use_w:
                C[a, b] /= N
            C[b, a] = C[a, b]
    return mean, C


@nb.njit(cache=True)
def mean_cov_rows(X):
    """Equal-weight mean (D,) and covariance (D,D) (divisor N) of the rows of X (N,D)."""
    return _mean_cov(X, X[:, 0], False)


@nb.njit(cache=True)
def weighted_mean_cov_rows(X, w):
    """Weighted mean ``Σ w_i x_i`` and covariance ``Σ w_i (x_i − x̄)(x_i − x̄)ᵀ`` of the rows of
    X (N,D) for normalised weights w (Bernard eq. 6.58–6.60)."""
    return _mean_cov(X, w, True)


@nb.njit(cache=True, parallel=True)
def liu_west_rows(eps, M, a, c, base, out):
    """``out[i] = a · base[i] + c + M eps[i]`` for eps (N,r), M (D,r), base (N,D), c (D,).

    With ``c = (1 − a) x̄`` and ``M = h L`` (``L Lᵀ`` the cloud covariance) this is the Liu &
    West (2001) shrinkage kernel; with a = 1, c = 0 a random-walk proposal. Parallel over rows.
    """
    N, r = eps.shape
    D = M.shape[0]
    for i in nb.prange(N):
        for d in range(D):
            acc = a * base[i, d] + c[d]
            for j in range(r):
                acc += M[d, j] * eps[i, j]
            out[i, d] = acc


# --------------------------------------------------------------------------------------------
# counter-based random numbers (Philox4x32-10)
# --------------------------------------------------------------------------------------------

_M0 = np.uint64(0xD2511F53)
_M1 = np.uint64(0xCD9E8D57)
_W0 = np.uint64(0x9E3779B9)
_W1 = np.uint64(0xBB67AE85)
_MASK = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)


@nb.njit(cache=True, inline="always")
def philox4x32(c0, c1, c2, c3, k0, k1):
    """Philox4x32-10 (Salmon et al. 2011) of the counter (c0…c3) under the key (k0, k1); all
    arguments and the four results are 32-bit values held in uint64."""
    for _ in range(10):
        p0 = _M0 * c0
        p1 = _M1 * c2
        hi0 = p0 >> _S32
        lo0 = p0 & _MASK
        hi1 = p1 >> _S32
        lo1 = p1 & _MASK
        c0 = (hi1 ^ c1 ^ k0) & _MASK
        c1 = lo1
        c2 = (hi0 ^ c3 ^ k1) & _MASK
        c3 = lo0
        k0 = (k0 + _W0) & _MASK
        k1 = (k1 + _W1) & _MASK
    return c0, c1, c2, c3


def _ziggurat_tables(n=128, r=3.442619855899, v=9.91256303526217e-3):
    """Layer edges ``x`` (n+1,) and ratios ``x[i+1]/x[i]`` (n,) of the 128-layer ziggurat of the
    standard normal density (Marsaglia & Tsang 2000; layer constants r, v and the layout with
    x[0] = v/f(r) for the base strip from Doornik 2005, "An improved ziggurat method to generate
    normal random samples")."""
    x = np.zeros(n + 1)
    f = math.exp(-0.5 * r * r)
    x[0] = v / f
    x[1] = r
    for i in range(2, n):
        x[i] = math.sqrt(-2.0 * math.log(v / x[i - 1] + f))
        f = math.exp(-0.5 * x[i] * x[i])
    return x, x[1:] / x[:-1]


_ZIG_X, _ZIG_R = _ziggurat_tables()
_ZIG_TAIL = 3.442619855899


@nb.njit(cache=True, inline="always")
def _u01_open(a, b):
    """A double in (0, 1) from two 32-bit words (never 0 or 1)."""
    hi = np.float64(a >> np.uint64(5))
    lo = np.float64(b >> np.uint64(6))
    return (hi * 67108864.0 + lo + 0.5) * (1.0 / 9007199254740992.0)


@nb.njit(cache=True, inline="always")
def _ziggurat_attempt(a, b, c, zr):
    """One ziggurat attempt's layer test from three Philox words → ``(u, i, accepted)``: the
    uniform u ∈ (−1, 1) from a, b, the layer i from c; the draw is ``u·zx[i]`` when accepted
    (:func:`ziggurat_normal`)."""
    u = 2.0 * _u01_open(a, b) - 1.0
    i = np.int64(c & np.uint64(127))
    return u, i, abs(u) < zr[i]


@nb.njit(cache=True, inline="always")
def ziggurat_normal(c0, c1, c2, c3, k0, k1, zx, zr):
    """One standard normal by the ziggurat method (Doornik 2005 variant, 128 layers) from the
    Philox4x32-10 stream of the counter (c0, c1 + 2¹⁶·attempt, c2, c3) under (k0, k1).

    Each attempt uses one Philox block: a uniform u ∈ (−1, 1) from two words, the layer from the
    third; ≈ 99 % of draws end in the first attempt with one multiply and one comparison. The
    base strip samples the tail beyond r by Marsaglia's (1964) method, the wedges by rejection
    against the density. ``zx``, ``zr``: :data:`_ZIG_X`, :data:`_ZIG_R`.
    """
    att = np.uint64(0)
    while True:
        a, b, c, d = philox4x32(c0, (c1 + (att << np.uint64(16))) & _MASK, c2, c3, k0, k1)
        att += np.uint64(1)
        u, i, accepted = _ziggurat_attempt(a, b, c, zr)
        if accepted:
            return u * zx[i]
        if i == 0:                      # the tail beyond r (Marsaglia 1964)
            while True:
                a, b, c, d = philox4x32(c0, (c1 + (att << np.uint64(16))) & _MASK, c2, c3,
                                        k0, k1)
                att += np.uint64(1)
                x = math.log(_u01_open(a, b)) / _ZIG_TAIL
                y = math.log(_u01_open(c, d))
                if -2.0 * y >= x * x:
                    return x - _ZIG_TAIL if u < 0.0 else _ZIG_TAIL - x
        x = u * zx[i]
        f0 = math.exp(-0.5 * (zx[i] * zx[i] - x * x))
        f1 = math.exp(-0.5 * (zx[i + 1] * zx[i + 1] - x * x))
        v = np.float64(d >> np.uint64(11)) * (1.0 / 2097152.0)   # 21-bit uniform in [0, 1)
        if f1 + v * (f0 - f1) < 1.0:
            return x


@nb.njit(cache=True, parallel=True, error_model="numpy")
def philox_normals_into(k0, k1, call, out, buf):
    """Fill ``out`` (N, r) with standard normals: entry (i, j) is the ziggurat normal
    (:func:`ziggurat_normal`) of the Philox4x32-10 counter ``(i, j, call mod 2³², call div
    2³²)`` under the key (k0, k1) — a pure function of (key, i, j, call), independent of the
    number of threads. ``buf``: scratch of at least N doubles.

    Two passes per column and chunk: the first attempt of every draw (one Philox block, the
    layer's comparison: ≈ 99 % of the draws end there) branch-free into the contiguous
    ``buf`` (so the compiler vectorises it across particles), with NaN where the attempt is
    rejected; then the column is written, with :func:`ziggurat_normal` for the rejected
    entries (it repeats the rejected attempt and goes on, so every entry is exactly its
    value).
    """
    N, r = out.shape
    kk0 = np.uint64(k0)
    kk1 = np.uint64(k1)
    cl = np.uint64(call) & _MASK
    ch = np.uint64(call) >> _S32
    zx = _ZIG_X
    zr = _ZIG_R
    nch = n_chunks(N)
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        for j in range(r):
            cj = np.uint64(j)
            for t in range(hi - lo):
                a, b, cc, _d = philox4x32(np.uint64(lo + t) & _MASK, cj, cl, ch, kk0, kk1)
                u, k, accepted = _ziggurat_attempt(a, b, cc, zr)
                buf[lo + t] = u * zx[k] if accepted else np.nan
            for t in range(hi - lo):
                v = buf[lo + t]
                if np.isnan(v):
                    v = ziggurat_normal(np.uint64(lo + t) & _MASK, cj, cl, ch, kk0, kk1, zx,
                                        zr)
                out[lo + t, j] = v


@nb.njit(cache=True)
def philox_normals(k0, k1, call, out):
    """:func:`philox_normals_into` with a scratch of its own (one allocation per call)."""
    philox_normals_into(k0, k1, call, out, np.empty(out.shape[0]))


@nb.njit(cache=True, parallel=True)
def philox_uniforms(k0, k1, call, out):
    """Fill ``out`` (N,) with uniforms in (0, 1): entry i from Philox4x32-10 of the counter
    ``(i, 2³² − 1, call mod 2³², call div 2³²)`` under (k0, k1) (the first two words)."""
    N = out.shape[0]
    kk0 = np.uint64(k0)
    kk1 = np.uint64(k1)
    cl = np.uint64(call) & _MASK
    ch = np.uint64(call) >> _S32
    for i in nb.prange(N):
        a, b, c, d = philox4x32(np.uint64(i) & _MASK, _MASK, cl, ch, kk0, kk1)
        out[i] = _u01_open(a, b)
