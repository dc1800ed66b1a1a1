"""Tests of lightcurve.estimation.particles (log weights, resampling, roughening, moments)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import special, stats

from lightcurve.errors import ConvergenceError
from lightcurve.estimation import (
    effective_sample_size,
    effective_sample_size_log,
    gaussian_log_likelihood,
    logsumexp,
    multinomial_resample,
    normalize_log_weights,
    resample,
    roughen,
    roughening_sigma,
    stratified_resample,
    systematic_resample,
    update_log_weights,
    weighted_mean_cov,
)

METHODS = ["systematic", "stratified", "multinomial"]


# ------------------------------------------------------------------------------ log weights

def test_logsumexp_stable_at_1e_minus_300_scale():
    # weights of order exp(-1e4) (far below the 1e-308 double range) must normalise exactly:
    # log(e^a + 2 e^a) = a + log 3 and weights 1/3, 2/3.
    a = np.array([-1e4, -1e4 + np.log(2.0)])
    with np.errstate(divide="ignore"):
        assert np.log(np.sum(np.exp(a))) == -np.inf  # the naive formula underflows
    assert logsumexp(a) == pytest.approx(-1e4 + np.log(3.0), rel=1e-15)
    w, lse = normalize_log_weights(a)
    # tolerance: the input -1e4 + log 2 itself is only known to one ulp of 1e4 (1.8e-12)
    np.testing.assert_allclose(w, [1 / 3, 2 / 3], rtol=1e-11)
    assert lse == pytest.approx(-1e4 + np.log(3.0), rel=1e-15)
    # random log weights near -1e4, checked against scipy.special.logsumexp (independent code)
    b = -1e4 + 50.0 * np.random.default_rng(0).standard_normal(10_000)
    assert logsumexp(b) == pytest.approx(special.logsumexp(b), rel=1e-14)
    wb, _ = normalize_log_weights(b)
    assert np.all(np.isfinite(wb)) and wb.sum() == pytest.approx(1.0, abs=1e-12)
    # -inf entries (impossible particles) are fine and get weight zero
    w2, _ = normalize_log_weights([-np.inf, -5e3, -5e3])
    np.testing.assert_array_equal(w2, [0.0, 0.5, 0.5])


def test_normalize_failure_paths():
    with pytest.raises(ConvergenceError):
        normalize_log_weights([-np.inf, -np.inf])
    with pytest.raises(ValueError, match="NaN"):
        normalize_log_weights([0.0, np.nan])
    with pytest.raises(ValueError):
        normalize_log_weights([])
    assert logsumexp([-np.inf, -np.inf]) == -np.inf


def test_effective_sample_size():
    # N_eff = 1/Σw² (Kong, Liu & Wong 1994): N for uniform weights, 1 for a single particle.
    assert effective_sample_size(np.full(100, 0.01)) == pytest.approx(100.0)
    assert effective_sample_size([0.0, 1.0, 0.0]) == pytest.approx(1.0)
    assert effective_sample_size([1.0, 1.0, 2.0]) == pytest.approx(16.0 / 6.0)
    lw = -1e4 + np.random.default_rng(1).standard_normal(500)
    w, _ = normalize_log_weights(lw)
    assert effective_sample_size_log(lw) == pytest.approx(1.0 / np.sum(w ** 2), rel=1e-10)


def test_gaussian_log_likelihood_matches_scipy():
    rng = np.random.default_rng(2)
    A = rng.standard_normal((3, 3))
    R = A @ A.T + 3 * np.eye(3)
    r = rng.standard_normal((50, 3))
    ref = stats.multivariate_normal(mean=np.zeros(3), cov=R).logpdf(r)
    np.testing.assert_allclose(gaussian_log_likelihood(r, R), ref, rtol=1e-12)
    # scalar measurement (magnitudes): R a variance
    r1 = rng.standard_normal(20)
    np.testing.assert_allclose(gaussian_log_likelihood(r1, 0.04),
                               stats.norm(0.0, 0.2).logpdf(r1), rtol=1e-12)
    lw0 = rng.standard_normal(50)
    np.testing.assert_allclose(update_log_weights(lw0, r, R), lw0 + ref, rtol=1e-12)
    with pytest.raises(ValueError, match="NaN"):
        update_log_weights(lw0[:2], [0.0, np.nan], 1.0)
    with pytest.raises(ValueError, match="positive definite"):
        gaussian_log_likelihood(r1, -1.0)


# ------------------------------------------------------------------------------ resampling

@settings(max_examples=60, deadline=None)
@given(w=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=40).filter(lambda v: sum(v) > 1e-6),
       n_out=st.integers(1, 60), seed=st.integers(0, 2**32 - 1))
def test_systematic_counts_within_floor_ceil(w, n_out, seed):
    # Deterministic property of systematic resampling (Kitagawa 1996; Douc & Cappé 2005):
    # particle i is copied ⌊n w_i⌋ or ⌈n w_i⌉ times; zero-weight particles never.
    w = np.asarray(w)
    wn = w / w.sum()
    idx = systematic_resample(w, seed, n_out=n_out)
    assert idx.shape == (n_out,) and np.all(np.diff(idx) >= 0)
    counts = np.bincount(idx, minlength=w.size)
    nw = n_out * wn
    assert np.all(counts >= np.floor(nw - 1e-9))
    assert np.all(counts <= np.ceil(nw + 1e-9))
    assert np.all(counts[w == 0.0] == 0)


@pytest.mark.parametrize("method", METHODS)
def test_resampling_basic_properties(method):
    w = np.array([0.0, 0.1, 0.0, 0.6, 0.3, 0.0])
    idx = resample(w, 7, method=method, n_out=1000)
    assert idx.shape == (1000,) and idx.dtype == np.int64
    assert np.all(np.diff(idx) >= 0)  # all three return sorted indices
    assert not np.any(np.isin(idx, [0, 2, 5]))  # zero weights are never drawn
    # bit-for-bit reproducibility for a seed, and a Generator's stream advances
    np.testing.assert_array_equal(idx, resample(w, 7, method=method, n_out=1000))
    g = np.random.default_rng(3)
    a = resample(w, g, method=method)
    b = resample(w, g, method=method)
    np.testing.assert_array_equal(a, resample(w, np.random.default_rng(3), method=method))
    assert a.shape == b.shape == (6,)
    with pytest.raises(ValueError, match="unknown resampling"):
        resample(w, 0, method="residualx")
    with pytest.raises(ValueError):
        resample([0.5, -0.1], 0, method=method)
    with pytest.raises(ValueError):
        resample([0.0, 0.0], 0, method=method)
    with pytest.raises(ValueError):
        resample([0.5, np.nan], 0, method=method)


def _unbiasedness_z(resampler, w, n_runs):
    """Max |z| of the mean counts over ``n_runs`` seeds against E[count_i] = N w_i."""
    N = w.size
    total = np.zeros(N)
    for s in range(n_runs):
        total += np.bincount(resampler(w, s), minlength=N)
    mean = total / n_runs
    pos = w > 0
    # Var[count_i] ≤ N w_i (1 − w_i) (multinomial; systematic and stratified have smaller
    # per-particle variance, Douc & Cappé 2005), so this z is conservative for all three.
    sd = np.sqrt(N * w[pos] * (1 - w[pos]) / n_runs)
    return np.max(np.abs(mean[pos] - N * w[pos]) / sd)


@pytest.mark.parametrize("method", METHODS)
def test_resampling_is_unbiased(method):
    # Unbiasedness: E[count_i] = N w_i (Bernard table 6.3; Douc & Cappé 2005). 2000 seeded
    # runs with N = 20 particles; per-particle z-tests, Bonferroni over the 19 particles with
    # non-zero weight, two-sided family-wise false-alarm rate 1e-3 (normal approximation of
    # the mean of 2000 bounded counts).
    w = np.random.default_rng(123).dirichlet(np.full(20, 0.7))
    w[5] = 0.0
    w /= w.sum()
    z_max_allowed = stats.norm.ppf(1 - 1e-3 / (2 * 19))
    f = {"systematic": systematic_resample, "stratified": stratified_resample,
         "multinomial": multinomial_resample}[method]
    assert _unbiasedness_z(f, w, 2000) < z_max_allowed


def test_unbiasedness_test_has_power():
    # The same statistic must reject a biased scheme (resampling from w^1.3 instead of w).
    w = np.random.default_rng(123).dirichlet(np.full(20, 0.7))

    def biased(w, s):
        v = w ** 1.3
        return systematic_resample(v / v.sum(), s)

    assert _unbiasedness_z(biased, w, 2000) > 10.0


# ------------------------------------------------------------------------------ roughening

def test_roughening_sigma_definition():
    # Gordon, Salmond & Smith (1993) / Bernard table 7.9: σ_j = G E_j N^(-1/d), E_j the range
    # of component j over the cloud.
    rng = np.random.default_rng(4)
    N, d = 1000, 3
    ranges = np.array([2.0, 0.5, 10.0])
    x = rng.random((N, d)) * ranges - 1.0
    x[0] = -1.0
    x[1] = ranges - 1.0  # exact min and max present, so E_j = ranges
    G = 0.2
    sig = roughening_sigma(x, G)
    np.testing.assert_allclose(sig, G * ranges * N ** (-1.0 / d), rtol=1e-12)
    np.testing.assert_allclose(roughening_sigma(x, G, d=6), G * ranges * N ** (-1 / 6),
                               rtol=1e-12)
    # the jitter has that standard deviation: Σ (Δ/σ)² over N·d values is χ²(N d);
    # two-sided bound with false-alarm rate 1e-3
    y, s2 = roughen(x, 99, G)
    np.testing.assert_array_equal(s2, sig)
    q = np.sum(((y - x) / sig) ** 2)
    lo, hi = stats.chi2.ppf([5e-4, 1 - 5e-4], N * d)
    assert lo < q < hi
    np.testing.assert_array_equal(y, roughen(x, 99, G)[0])  # reproducible
    z0, _ = roughen(x, 1, 0.0)
    np.testing.assert_array_equal(z0, x)  # G = 0: unchanged
    with pytest.raises(ValueError):
        roughening_sigma(x, -1.0)


# ------------------------------------------------------------------------------ moments

def test_weighted_mean_cov_matches_numpy():
    rng = np.random.default_rng(5)
    x = rng.standard_normal((300, 4)) @ rng.standard_normal((4, 4))
    w = rng.random(300)
    wn = w / w.sum()
    m, C = weighted_mean_cov(x, w)
    np.testing.assert_allclose(m, np.average(x, axis=0, weights=wn), rtol=1e-12)
    np.testing.assert_allclose(C, np.cov(x.T, aweights=wn, bias=True), rtol=1e-10, atol=1e-12)
    _, Cu = weighted_mean_cov(x, w, unbiased=True)
    np.testing.assert_allclose(Cu, np.cov(x.T, aweights=wn, ddof=1), rtol=1e-10, atol=1e-12)
    with pytest.raises(ValueError):
        weighted_mean_cov(x, w[:10])
