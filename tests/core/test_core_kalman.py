"""Core Kalman kernels (lightcurve.core.kalman, lightcurve.core.sigma_points) against the
textbook Kalman update written in plain NumPy here (Bar-Shalom, Li & Kirubarajan 2001 §5.2),
the Schmidt consider update (O'Keefe 2015 §3.2.2) and NumPy's LAPACK factorisations."""

import numpy as np

from lightcurve.core import kalman as K
from lightcurve.core import sigma_points as SP

RNG = np.random.default_rng(5)


def _spd(n):
    A = RNG.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def test_cholesky_and_inverses_match_lapack_and_flag_failures():
    A = _spd(6)
    L, ok = K.cholesky_nb(A)
    assert ok
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-13)
    for f in (K.inverse_nb, K.spd_inverse_nb):
        X, ok = f(A)
        assert ok
        np.testing.assert_allclose(X, np.linalg.inv(A), rtol=1e-12, atol=1e-15)
    bad = np.diag([1.0, -1.0, 2.0])
    assert not K.cholesky_nb(bad)[1]
    assert not K.spd_inverse_nb(bad)[1]
    assert K.inverse_nb(bad)[1]                      # invertible, only not positive definite
    assert not K.inverse_nb(np.array([[1.0, 2.0], [2.0, 4.0]]))[1]
    nan = A.copy()
    nan[2, 2] = np.nan
    L, ok = K.cholesky_nb(nan)
    assert not ok and np.all(L == 0)


def _textbook(x, P, nu, H, R):
    S = H @ P @ H.T + R
    Kg = P @ H.T @ np.linalg.inv(S)
    I = np.eye(len(x))
    return x + Kg @ nu, (I - Kg @ H) @ P @ (I - Kg @ H).T + Kg @ R @ Kg.T, nu @ np.linalg.solve(S, nu)


def test_joseph_vector_update_equals_textbook_and_scalar_fast_path():
    n, m = 7, 3
    x, P = RNG.normal(size=n), _spd(n)
    H, R = RNG.normal(size=(m, n)), _spd(m)
    nu = RNG.normal(size=m)
    xn, Pn, nis, ok = K.joseph_update_nb(x, P, nu, H, R, np.zeros(n, np.bool_))
    ex, eP, enis = _textbook(x, P, nu, H, R)
    assert ok
    np.testing.assert_allclose(xn, ex, rtol=1e-12)
    np.testing.assert_allclose(Pn, eP, rtol=1e-11, atol=1e-13)
    assert np.isclose(nis, enis, rtol=1e-12)
    np.testing.assert_array_equal(Pn, Pn.T)
    # scalar fast path: the same update for m = 1 from a zero error state
    h, r, v = RNG.normal(size=n), 0.7, 0.3
    dx, P1 = np.empty(n), np.empty((n, n))
    S, status = K.joseph_scalar_nb(P, h, r, v, dx, P1)
    ex, eP, _ = _textbook(np.zeros(n), P, np.array([v]), h[None], np.array([[r]]))
    assert status == K.UPDATE_OK and np.isclose(S, h @ P @ h + r)
    np.testing.assert_allclose(dx, ex, rtol=1e-12)
    np.testing.assert_allclose(P1, eP, rtol=1e-11, atol=1e-13)


def test_schmidt_consider_update_keeps_considered_block():
    # O'Keefe §3.2.2: considered parameters keep estimate and covariance; their
    # cross-covariance becomes (I − K H) P_xc; the Joseph form is exact for this gain
    n = 5
    x, P = RNG.normal(size=n), _spd(n)
    H, R = RNG.normal(size=(2, n)), _spd(2)
    nu = RNG.normal(size=2)
    cons = np.array([False, False, False, True, True])
    xn, Pn, _, ok = K.joseph_update_nb(x, P, nu, H, R, cons)
    assert ok
    np.testing.assert_array_equal(xn[3:], x[3:])
    np.testing.assert_allclose(Pn[3:, 3:], P[3:, 3:], rtol=1e-12)
    S = H @ P @ H.T + R
    Kx = (P @ H.T @ np.linalg.inv(S))[:3]
    Kf = np.vstack([Kx, np.zeros((2, 2))])
    I = np.eye(n)
    np.testing.assert_allclose(Pn, (I - Kf @ H) @ P @ (I - Kf @ H).T + Kf @ R @ Kf.T, rtol=1e-11)


def test_refused_updates_return_the_prior():
    n = 4
    x, P = RNG.normal(size=n), _spd(n)
    H = RNG.normal(size=(1, n))
    xn, Pn, nis, ok = K.joseph_update_nb(x, P, np.array([np.nan]), H, np.eye(1),
                                         np.zeros(n, np.bool_))
    assert not ok and np.isnan(nis)
    np.testing.assert_array_equal(xn, x)
    np.testing.assert_array_equal(Pn, P)
    xn, Pn, nis, ok = K.joseph_update_nb(x, P, np.array([1.0]), np.zeros((1, n)), -np.eye(1),
                                         np.zeros(n, np.bool_))
    assert not ok
    dx, P1 = np.empty(n), np.empty((n, n))
    assert K.joseph_scalar_nb(P, H[0], 1.0, np.inf, dx, P1)[1] == K.UPDATE_BAD_INNOVATION
    assert K.joseph_scalar_nb(P, np.zeros(n), -1.0, 0.1, dx, P1)[1] == K.UPDATE_BAD_S


def test_unscented_weights_and_points_reproduce_mean_and_covariance():
    # Bernard eq. 7.51–7.59: the 2n+1 points reproduce the first two moments exactly
    n = 6
    for alpha, beta, kappa in ((1.0, 2.0, 0.0), (0.5, 2.0, 1.0)):
        lam, wm, wc = SP.unscented_weights_nb(n, alpha, beta, kappa)
        assert np.isclose(lam, alpha ** 2 * (n + kappa) - n)
        assert np.isclose(wm.sum(), 1.0)
        P, x = _spd(n), RNG.normal(size=n)
        off, ok = SP.sigma_offsets_nb(P, n + lam)
        assert ok
        X = np.vstack([x, x + off])
        mean, C = SP.weighted_mean_cov_nb(X, wm, wc - np.r_[1.0 - alpha ** 2 + beta, np.zeros(2 * n)])
        np.testing.assert_allclose(mean, x, atol=1e-12)
        np.testing.assert_allclose(C, P, rtol=1e-10)
    assert not SP.sigma_offsets_nb(-np.eye(3), 3.0)[1]
