"""Gyro models (O'Keefe eq. 2.23-2.50) and Allan variance (eq. 2.52) with noise recovery."""

import numpy as np
import pytest

from lightcurve.css.allan import allan_variance, fit_arw_rrw
from lightcurve.css.gyro import (GYRO_GRADES, GyroErrors, GyroSpec, draw_gyro_errors,
                                 gyro_grade, simulate_gyro)


def test_allan_variance_matches_inline_definition():
    # independent inline eq. 2.52 on a short random series
    rng = np.random.default_rng(0)
    w = rng.normal(size=200)
    tau0 = 0.5
    tau, av, _ = allan_variance(w, tau0, m=np.array([1, 3, 10]))
    th = np.concatenate([[0.0], np.cumsum(w) * tau0])
    for t, a, m in zip(tau, av, (1, 3, 10)):
        s = sum((th[k + 2 * m] - 2 * th[k + m] + th[k]) ** 2 for k in range(len(th) - 2 * m))
        assert a == pytest.approx(s / (2 * t * t * (len(th) - 2 * m)), rel=1e-12)
    # m = 1 of white rate noise: sigma^2(tau0) = var(w) (exact in expectation); 200 samples
    # -> relative sd of the estimate ~ sqrt(2/199)*1.2 ~ 0.12; 4 sd bound
    assert av[0] == pytest.approx(1.0, abs=0.5)


def test_farrenkopf_recovery_of_arw_and_rrw():
    # simulate a pure Farrenkopf gyro at rest, recover N and K from the Allan curve.
    spec = GyroSpec("test", arw=1e-3, rrw=2e-5, bias_sigma=0.0)
    dt, K = 0.1, 200_000  # 20 000 s
    w, _ = simulate_gyro(np.zeros((K, 3)), dt, spec, rng=11, detailed=False)
    tau, av, n = allan_variance(w, dt)
    N_hat, K_hat = [], []
    for ax in range(3):
        a, b = fit_arw_rrw(tau, av[:, ax], K, tau0=dt)
        N_hat.append(a)
        K_hat.append(b)
    # ARW is estimated from ~2e5 samples: a few percent; RRW from the long-tau end (about 20
    # independent clusters at tau = 1000 s): 25 % bound (~3 sigma of the fitted K).
    assert np.allclose(N_hat, 1e-3, rtol=0.05)
    assert np.allclose(K_hat, 2e-5, rtol=0.25)
    # read-off at tau = 1 s on the -1/2 slope is ARW (IEEE 952): within 10 %
    i1 = np.argmin(abs(tau - 1.0))
    assert np.sqrt(av[i1, 0] * tau[i1]) == pytest.approx(1e-3, rel=0.1)


def test_farrenkopf_discrete_statistics():
    # Crassidis & Junkins eq. 4.31: with zero bias drift the sample noise is sigma_v/sqrt(dt)
    spec = GyroSpec("t", arw=2e-3, rrw=0.0, bias_sigma=0.0)
    w, b = simulate_gyro(np.ones((20000, 3)) * 0.01, 0.25, spec, rng=2, detailed=False)
    r = (w - 0.01).ravel()
    sd = 2e-3 / np.sqrt(0.25)
    assert abs(r.var() / sd ** 2 - 1) < 4 * np.sqrt(2 / r.size)  # 4-sigma chi-square bound
    assert np.all(b == 0)
    # bias random walk: var(beta_K) = rrw^2 K dt
    spec = GyroSpec("t", arw=0.0, rrw=1e-4, bias_sigma=0.0)
    finals = np.array([simulate_gyro(np.zeros((400, 3)), 1.0, spec, rng=s, detailed=False)[1][-1]
                       for s in range(60)]).ravel()
    var = finals.var()
    assert abs(var / (1e-8 * 400) - 1) < 4 * np.sqrt(2 / finals.size)


def test_detailed_model_scale_and_misalignment():
    spec = GyroSpec("t", arw=0.0, rrw=0.0, bias_sigma=0.0)
    M = np.array([[1.01, 0.002, -0.001], [0.0005, 0.99, 0.003], [0.0, -0.002, 1.0]])
    err = GyroErrors(M, np.array([1e-3, -2e-3, 0.0]))
    om = np.array([[0.1, -0.2, 0.3]])
    w, _ = simulate_gyro(om, 1.0, spec, rng=0, errors=err)
    assert np.allclose(w[0], M @ om[0] + err.bias0, atol=1e-15)
    e = draw_gyro_errors(GYRO_GRADES["rate"], 5)
    assert not np.allclose(e.M, np.eye(3)) and np.allclose(np.diag(e.M), 1, atol=5e-3)
    e = draw_gyro_errors(GYRO_GRADES["rate"], 5, detailed=False)
    assert np.array_equal(e.M, np.eye(3))


def test_grades_ordered():
    r, t, n = (gyro_grade(k) for k in ("rate", "tactical", "navigation"))
    assert r.arw > t.arw > n.arw and r.bias_sigma > t.bias_sigma > n.bias_sigma
    with pytest.raises(ValueError):
        gyro_grade("consumer")
