"""Monte Carlo tuning helpers (lightcurve.estimation.tuning) on a scalar random walk observed
in white noise, where the Kalman filter is exactly consistent when its R equals the truth's
(Bar-Shalom et al. 2001 §5.4.2: NEES ~ χ²_n, NIS ~ χ²_m)."""

import numpy as np

from lightcurve.estimation.tuning import consistency_summary, nis_ratio, tune_parameter


def _kf_runs(r_filter, r_true=0.04, q=0.01, n_runs=40, T=200, seed=0):
    rng = np.random.default_rng(seed)
    errs = np.zeros((n_runs, T, 1))
    Ps = np.zeros((n_runs, T, 1, 1))
    nus = np.zeros((n_runs, T, 1))
    Ss = np.zeros((n_runs, T, 1, 1))
    for i in range(n_runs):
        x, xh, P = rng.normal(0, 1.0), 0.0, 1.0
        for k in range(T):
            x += rng.normal(0, np.sqrt(q))
            P += q
            y = x + rng.normal(0, np.sqrt(r_true))
            S = P + r_filter
            nu = y - xh
            K = P / S
            xh += K * nu
            P = (1 - K) * P
            errs[i, k, 0], Ps[i, k, 0, 0] = x - xh, P
            nus[i, k, 0], Ss[i, k, 0, 0] = nu, S
    return errs, Ps, nus, Ss


def test_consistent_filter_inside_bands_and_mistuned_outside():
    e, P, v, S = _kf_runs(0.04)
    s = consistency_summary(e, P, v, S, prob=0.95)
    # ~95 % of epochs inside the bands for the exactly tuned filter
    assert s["nees_inside"] > 0.85 and s["nis_inside"] > 0.85 and s["nmee_inside"] > 0.85
    e, P, v, S = _kf_runs(0.004)  # R ten times too small: over-confident
    s = consistency_summary(e, P, v, S, prob=0.95)
    assert s["nis_inside"] < 0.3
    r, lo, hi = nis_ratio(s["nis"] * 0 + np.mean(s["nis"]))
    assert r > 2


def test_nis_ratio_interval_and_tuning_recovers_true_noise():
    rng = np.random.default_rng(1)
    r, lo, hi = nis_ratio(rng.chisquare(2, 5000), dof=2)
    assert lo < r < hi and lo < 1 < hi

    def run(r_f):
        _, _, v, S = _kf_runs(r_f, n_runs=10, T=150, seed=3)
        return (v[..., 0] ** 2 / S[..., 0, 0]).ravel()

    best, table = tune_parameter(run, [0.01, 0.02, 0.04, 0.08, 0.16])
    assert best == 0.04
    assert table[0][1] > 1 > table[-1][1]
