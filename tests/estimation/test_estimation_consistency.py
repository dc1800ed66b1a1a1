"""Tests of lightcurve.estimation.consistency (NEES, NIS, NMEE, χ² bounds, NIS detector)."""

import numpy as np
import pytest
from scipy import stats

from lightcurve.estimation import (
    NISDivergenceDetector,
    averaged_nees,
    chi2_consistency,
    chi2_interval,
    nees,
    nis,
    nmee,
    nmee_interval,
    windowed_average,
)


def test_chi2_interval_table_values_and_scipy():
    # Printed χ² tables (Abramowitz & Stegun 1964, table 26.8): χ²₁₀(0.025) = 3.247,
    # χ²₁₀(0.975) = 20.483; χ²₁₀₀(0.025) = 74.222, χ²₁₀₀(0.975) = 129.561.
    lo, hi = chi2_interval(10, 0.95)
    assert lo == pytest.approx(3.247, abs=5e-4) and hi == pytest.approx(20.483, abs=5e-4)
    # averaged over N = 50 runs of a 2-state NEES (Bar-Shalom et al. 2001 §5.4.2): 100 dof / 50
    lo, hi = chi2_interval(2, 0.95, n_avg=50)
    assert lo == pytest.approx(74.222 / 50, abs=1e-4)
    assert hi == pytest.approx(129.561 / 50, abs=1e-4)
    for dof, prob, n in [(1, 0.99, 1), (3, 0.95, 100), (6, 0.999, 25)]:
        lo, hi = chi2_interval(dof, prob, n)
        a = (1 - prob) / 2
        assert lo == stats.chi2.ppf(a, dof * n) / n
        assert hi == stats.chi2.ppf(1 - a, dof * n) / n
    with pytest.raises(ValueError):
        chi2_interval(0)
    with pytest.raises(ValueError):
        chi2_interval(2, 1.5)


def test_nees_nis_against_explicit_inverse():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((7, 3, 3))
    P = A @ np.swapaxes(A, -1, -2) + np.eye(3)
    e = rng.standard_normal((7, 3))
    ref = np.einsum("ti,tij,tj->t", e, np.linalg.inv(P), e)
    np.testing.assert_allclose(nees(e, P), ref, rtol=1e-10)
    np.testing.assert_allclose(nis(e, P), ref, rtol=1e-10)
    # broadcasting one covariance over many vectors
    np.testing.assert_allclose(nees(e, P[0]), np.einsum("ti,ij,tj->t", e, np.linalg.inv(P[0]), e),
                               rtol=1e-10)
    # scalar innovations with scalar variances
    np.testing.assert_allclose(nis(np.array([1.0, 2.0]), np.array([4.0, 0.5])), [0.25, 8.0])
    with pytest.raises(ValueError, match="positive definite"):
        nees([1.0, 1.0], np.diag([1.0, -1.0]))


def test_averaged_nees_of_consistent_errors_lies_in_band():
    # Errors drawn from N(0, P) are consistent by construction: each epoch's average over
    # N = 50 runs lies in the 95 % interval with probability 0.95. Over 200 independent
    # epochs the share inside is Binomial(200, 0.95)/200; accept above its 1e-3 quantile.
    rng = np.random.default_rng(42)
    N, T, n = 50, 200, 3
    A = rng.standard_normal((T, n, n))
    P = A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(n)
    L = np.linalg.cholesky(P)
    e = np.einsum("tij,rtj->rti", L, rng.standard_normal((N, T, n)))
    res = chi2_consistency(averaged_nees(e, np.broadcast_to(P, (N, T, n, n))), n, N, 0.95)
    assert res.fraction_inside >= stats.binom.ppf(1e-3, T, 0.95) / T
    # power: a filter claiming half the true covariance is rejected
    bad = chi2_consistency(averaged_nees(e, 0.5 * np.broadcast_to(P, (N, T, n, n))), n, N)
    assert bad.fraction_inside < 0.2 and not bad.consistent


def test_nmee_band():
    # NMEE components of consistent errors are N(0, 1/N) (O'Keefe 2015 eq. 5.1–5.11); with
    # independent components and epochs, the share inside the 95 % band is
    # Binomial(T n, 0.95)/(T n); accept above its 1e-3 quantile.
    rng = np.random.default_rng(7)
    N, T, n = 40, 100, 3
    sig = np.array([0.1, 2.0, 30.0])
    e = rng.standard_normal((N, T, n)) * sig
    P = np.broadcast_to(np.diag(sig ** 2), (N, T, n, n))
    mu = nmee(e, P)
    np.testing.assert_allclose(mu, nmee(e, np.broadcast_to(sig, (N, T, n))))
    lo, hi = nmee_interval(N, 0.95)
    assert hi == pytest.approx(1.959964 / np.sqrt(N), rel=1e-6) and lo == -hi
    frac = np.mean((mu >= lo) & (mu <= hi))
    assert frac >= stats.binom.ppf(1e-3, T * n, 0.95) / (T * n)
    # a biased estimator (errors offset by one sigma) is rejected
    mu_b = nmee(e + sig, P)
    assert np.mean((mu_b >= lo) & (mu_b <= hi)) < 0.05


def test_windowed_average_matches_naive_loop():
    rng = np.random.default_rng(3)
    v = rng.random(200)
    v[rng.random(200) < 0.2] = np.nan
    v[:3] = np.nan
    avg, cnt = windowed_average(v, 7)
    valid = []
    for t in range(v.size):
        if np.isfinite(v[t]):
            valid.append(v[t])
        last = valid[-7:]
        assert cnt[t] == len(last)
        if last:
            assert avg[t] == pytest.approx(np.mean(last), rel=1e-12)
        else:
            assert np.isnan(avg[t])


def test_nis_detector_false_alarm_rate():
    # One full-window test on a consistent filter (NIS ~ χ²₁, window 20, two-sided 99 % band)
    # fires with probability 0.005. 2000 independent windows: the number of alarms is
    # Binomial(2000, 0.005); accept below its 1 - 1e-3 quantile (false-alarm rate 1e-3).
    rng = np.random.default_rng(10)
    det = NISDivergenceDetector(dof=1, window=20, prob=0.99)
    assert det.hi == pytest.approx(stats.chi2.ppf(0.995, 20) / 20)
    alarms = 0
    for _ in range(2000):
        flags = det.run(rng.chisquare(1, size=20))
        assert not flags[:-1].any()  # no decision before the window is full
        alarms += bool(flags[-1])
    assert alarms <= stats.binom.ppf(1 - 1e-3, 2000, 0.005)


def test_nis_detector_detects_fault_and_skips_nan():
    # A fault that quadruples the NIS from step 500 on (e.g. a sensor stuck, O'Keefe §5.1)
    # must be flagged within 40 steps; with the fixed seed there is no alarm before it.
    rng = np.random.default_rng(11)
    v = rng.chisquare(1, size=1000)
    v[500:] *= 4.0
    v[100:110] = np.nan  # missing measurements do not count
    det = NISDivergenceDetector(dof=1, window=20, prob=0.99)
    flags = det.run(v)
    first = NISDivergenceDetector.first_flag(flags)
    assert first is not None and 500 <= first < 540
    assert NISDivergenceDetector.first_flag(np.zeros(5, bool)) is None
    with pytest.raises(ValueError):
        det.update(-1.0)


def test_order_statistic_interval_covers_the_sample_median_at_its_rate():
    """The exact interval of the ⌈n/2⌉-th order statistic of n χ²₁ variables (Beta law of F(X_(k)),
    David & Nagaraja 2003 §2.1) against 20,000 simulated medians (n = 73, fixed seed): the
    fraction outside the 99 % interval is 1 % ± 0.3 % (4.2 binomial σ: false-alarm rate < 1e-4);
    for k = n it is the χ²₁ quantile of the maximum, (F⁻¹(((1 ∓ p)/2)^(1/n)))."""
    from lightcurve.estimation.consistency import order_statistic_interval

    n, k = 73, 37
    lo, hi = order_statistic_interval(1, k, n, 0.99)
    rng = np.random.default_rng(8)
    med = np.sort(rng.chisquare(1, size=(20000, n)), axis=1)[:, k - 1]
    out = np.mean((med < lo) | (med > hi))
    assert abs(out - 0.01) < 0.003, out
    lo_m, hi_m = order_statistic_interval(1, n, n, 0.99)
    assert hi_m == pytest.approx(stats.chi2.ppf(0.995 ** (1 / n), 1), rel=1e-9)
    assert lo_m == pytest.approx(stats.chi2.ppf(0.005 ** (1 / n), 1), rel=1e-9)
