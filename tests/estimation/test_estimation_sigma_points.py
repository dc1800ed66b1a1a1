"""Tests of lightcurve.estimation.sigma_points (scaled unscented transform, USQUE helpers)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lightcurve.estimation import (
    augment,
    joseph_update,
    sigma_offsets,
    sigma_points,
    split_augmented,
    unscented_transform,
    unscented_update,
    unscented_weights,
)


def random_spd(rng, n, scale=1.0):
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T + n * np.eye(n))


def test_weight_values():
    # Wan & van der Merwe (2000) weights with n = 3, α = 1, β = 2, κ = 0: λ = 0,
    # W0m = 0, Wim = 1/6, W0c = 0 + 1 - 1 + 2 = 2.
    w = unscented_weights(3, alpha=1.0, beta=2.0, kappa=0.0)
    assert w.lam == 0.0
    assert w.wm[0] == 0.0 and w.wc[0] == 2.0
    np.testing.assert_allclose(w.wm[1:], 1.0 / 6.0)
    assert w.gamma == pytest.approx(np.sqrt(3.0))
    # α = 1e-3, n = 6 (GRP + rate): λ = 1e-6·6 − 6, weights still sum to one
    w6 = unscented_weights(6, alpha=1e-3, beta=2.0, kappa=0.0)
    assert w6.lam == pytest.approx(6e-6 - 6.0)
    assert w6.wm.sum() == pytest.approx(1.0, abs=1e-9)
    assert w6.n_points == 13
    with pytest.raises(ValueError, match="n \\+ lambda"):
        unscented_weights(3, alpha=1.0, kappa=-3.0)
    with pytest.raises(ValueError):
        unscented_weights(0)


def test_sigma_points_layout_and_moments():
    rng = np.random.default_rng(4)
    P = random_spd(rng, 4)
    x = rng.standard_normal(4)
    w = unscented_weights(4, alpha=0.5, beta=2.0, kappa=1.0)
    chi, ok = sigma_points(x, P, w)
    assert ok and chi.shape == (9, 4)
    np.testing.assert_array_equal(chi[0], x)
    np.testing.assert_allclose(chi[1:5] - x, -(chi[5:] - x), atol=1e-14)
    # the points reproduce the mean and covariance exactly (Julier & Uhlmann 2004)
    np.testing.assert_allclose(w.wm @ chi, x, atol=1e-12)
    D = chi[1:] - x
    np.testing.assert_allclose((D * w.wm[1:, None]).T @ D, P, atol=1e-10)
    off, ok = sigma_offsets(P, w)
    np.testing.assert_allclose(off, chi[1:] - x, atol=1e-14)


def test_non_pd_covariance_reports_failure():
    w = unscented_weights(2)
    assert sigma_points([0.0, 0.0], np.diag([1.0, -1.0]), w) == (None, False)
    r = unscented_transform(lambda c: c, [0.0, 0.0], np.diag([1.0, -1.0]), w)
    assert not r.ok and r.mean is None
    # f producing NaN is also a reported failure, not a NaN mean
    with np.errstate(invalid="ignore"):
        r2 = unscented_transform(lambda c: np.log(c - 10.0), [0.0, 0.0], np.eye(2), w)
    assert not r2.ok and r2.mean is None


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 5), m=st.integers(1, 4),
       alpha=st.sampled_from([1e-3, 0.1, 0.5, 1.0]), kappa=st.sampled_from([0.0, 1.0, 2.0]))
def test_linear_map_is_exact(seed, n, m, alpha, kappa):
    # Julier & Uhlmann (2004): the UT is exact for linear maps, y = A x + b ⇒
    # ȳ = A x̄ + b, P_yy = A P Aᵀ, P_xy = P Aᵀ, for any α, β, κ.
    rng = np.random.default_rng(seed)
    P = random_spd(rng, n)
    x = rng.standard_normal(n)
    A = rng.standard_normal((m, n))
    b = rng.standard_normal(m)
    w = unscented_weights(n, alpha=alpha, beta=2.0, kappa=kappa)
    r = unscented_transform(lambda c: c @ A.T + b, x, P, w)
    assert r.ok
    sc = np.abs(P).max() * (1 + np.abs(A).max()) ** 2
    # with small α the weights are ±O(1/α²): round-off grows like 1/α²
    tol = 1e-12 * sc / min(alpha, 1.0) ** 2
    np.testing.assert_allclose(r.mean, A @ x + b, atol=tol + 1e-9)
    np.testing.assert_allclose(r.cov, A @ P @ A.T, atol=tol)
    np.testing.assert_allclose(r.cross, P @ A.T, atol=tol)


@pytest.mark.parametrize("alpha,beta,kappa", [(1.0, 0.0, 2.0), (1.0, 2.0, 0.0),
                                              (1e-3, 2.0, 0.0), (0.5, 2.0, 0.0)])
def test_quadratic_second_moment_scalar(alpha, beta, kappa):
    # x ~ N(μ, P), y = x²: E y = μ² + P, Var y = 4μ²P + 2P², Cov(x, y) = 2μP
    # (Gaussian moments). Julier & Uhlmann (1997): with n + κ = 3 the UT matches the fourth
    # moment and so the variance exactly; in the scaled form β = 2 restores it for any α.
    mu, P = 0.7, 2.0
    w = unscented_weights(1, alpha=alpha, beta=beta, kappa=kappa)
    r = unscented_transform(lambda c: c[:, 0] ** 2, [mu], [[P]], w)
    assert r.mean[0] == pytest.approx(mu ** 2 + P, rel=1e-6)
    assert r.cov[0, 0] == pytest.approx(4 * mu ** 2 * P + 2 * P ** 2, rel=1e-6)
    assert r.cross[0, 0] == pytest.approx(2 * mu * P, rel=1e-6)


def test_quadratic_form_mean_multivariate():
    # E[xᵀ A x] = tr(A P) + μᵀ A μ for x ~ N(μ, P): the UT mean is exact to second order.
    rng = np.random.default_rng(8)
    n = 4
    P = random_spd(rng, n)
    mu = rng.standard_normal(n)
    A = random_spd(rng, n)
    w = unscented_weights(n, alpha=1.0, beta=2.0, kappa=3.0 - n)
    r = unscented_transform(lambda c: np.einsum("ij,jk,ik->i", c, A, c), mu, P, w)
    assert r.mean[0] == pytest.approx(np.trace(A @ P) + mu @ A @ mu, rel=1e-10)
    # and a wrong moment would be noticed: the first-order (EKF) mean differs by tr(AP)
    assert abs(r.mean[0] - mu @ A @ mu) > 1.0


def test_augmented_noise_equals_additive_noise():
    # USQUE-style augmentation (Crassidis & Markley 2003; Bernard eq. 7.83-7.87): appending
    # zero-mean noise w ~ N(0, Q) to the state and mapping (x, w) → A x + w gives the same
    # moments as the additive form A P Aᵀ + Q.
    rng = np.random.default_rng(9)
    n = 3
    P = random_spd(rng, n)
    Q = random_spd(rng, n, 0.1)
    x = rng.standard_normal(n)
    A = rng.standard_normal((n, n))
    xa, Pa, sizes = augment(x, P, Q)
    assert sizes == (3, 3) and xa.shape == (6,)
    np.testing.assert_array_equal(Pa[:3, 3:], 0.0)
    wa = unscented_weights(6, alpha=1.0, beta=2.0, kappa=0.0)

    def f(chi):
        xs, ws = split_augmented(chi, sizes)
        return xs @ A.T + ws

    r = unscented_transform(f, xa, Pa, wa)
    np.testing.assert_allclose(r.mean, A @ x, atol=1e-12)
    np.testing.assert_allclose(r.cov, A @ P @ A.T + Q, atol=1e-10)
    # scalar and diagonal noise blocks
    _, Pa2, sizes2 = augment(x, P, 0.5, [1.0, 2.0])
    assert sizes2 == (3, 1, 2)
    np.testing.assert_allclose(np.diag(Pa2)[3:], [0.5, 1.0, 2.0])
    with pytest.raises(ValueError):
        split_augmented(np.zeros((2, 5)), sizes)


def test_unscented_update_equals_kalman_for_linear_measurement():
    # For a linear measurement, P_yy = H P Hᵀ + R and P_xy = P Hᵀ exactly, so the UKF update
    # equals the Kalman update (Bar-Shalom et al. 2001 §5.2; Wan & van der Merwe 2000).
    rng = np.random.default_rng(12)
    n, m = 4, 2
    P = random_spd(rng, n)
    H = rng.standard_normal((m, n))
    R = random_spd(rng, m, 0.3)
    x = rng.standard_normal(n)
    y = rng.standard_normal(m)
    w = unscented_weights(n, alpha=1.0, beta=2.0, kappa=0.0)
    chi, ok = sigma_points(x, P, w)
    Y = chi @ H.T
    xu, Pu, iu = unscented_update(x, P, chi, Y, y, w, R=R)
    xk, Pk, ik = joseph_update(x, P, y, H, R)
    assert iu.ok
    np.testing.assert_allclose(xu, xk, atol=1e-10)
    np.testing.assert_allclose(Pu, Pk, atol=1e-10)
    assert iu.nis == pytest.approx(ik.nis, rel=1e-9)
    # failure path: a negative R makes P_yy indefinite → prior returned unchanged
    xf, Pf, fi = unscented_update(x, P, chi, Y, y, w, R=-1e3 * np.eye(m))
    assert not fi.ok
    np.testing.assert_array_equal(xf, x)
    np.testing.assert_array_equal(Pf, P)
