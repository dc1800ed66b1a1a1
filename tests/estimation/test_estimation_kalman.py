"""Tests of lightcurve.estimation.kalman (updates, predict, safe Cholesky, numba kernels)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lightcurve.estimation import (
    consider_update,
    joseph_update,
    kf_predict,
    safe_cholesky,
    symmetrize,
)
from lightcurve.estimation.kalman import cholesky_nb, joseph_update_nb


def standard_update(x, P, y, H, R):
    """Reference: the short-form update ``P⁺ = (I − K H) P`` (Bar-Shalom et al. 2001 §5.2.3),
    plain NumPy; returns ``(x⁺, P⁺, ok)`` (ok False when S is not positive definite)."""
    x, P, H = np.asarray(x, float), np.asarray(P, float), np.atleast_2d(np.asarray(H, float))
    y = np.atleast_1d(np.asarray(y, float))
    R = np.asarray(R, float) * np.eye(y.size) if np.ndim(R) == 0 else np.asarray(R, float)
    S = H @ P @ H.T + R
    if np.any(np.linalg.eigvalsh(0.5 * (S + S.T)) <= 0):
        return x, P, False
    K = P @ H.T @ np.linalg.inv(S)
    return x + K @ (y - H @ x), (np.eye(x.size) - K @ H) @ P, True


def random_spd(rng, n, scale=1.0):
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T + n * np.eye(n))


def test_scalar_update_matches_two_measurement_fusion():
    # Maybeck (1979), Stochastic Models, Estimation and Control vol. 1, §1.5 example:
    # combining a prior z1 with
    # variance s1 and a measurement z2 with variance s2 gives
    #   x = (s2 z1 + s1 z2)/(s1 + s2),  1/s = 1/s1 + 1/s2.
    z1, s1, z2, s2 = 10.0, 4.0, 12.0, 1.0
    x, P, info = joseph_update([z1], [[s1]], z2, [1.0], s2)
    assert info.ok
    assert x[0] == pytest.approx((s2 * z1 + s1 * z2) / (s1 + s2), rel=1e-14)  # 11.6
    assert P[0, 0] == pytest.approx(1.0 / (1.0 / s1 + 1.0 / s2), rel=1e-14)  # 0.8
    assert info.gain[0, 0] == pytest.approx(s1 / (s1 + s2))  # K = 0.8
    assert info.innovation[0] == pytest.approx(2.0)
    assert info.S[0, 0] == pytest.approx(5.0)
    assert info.nis == pytest.approx(4.0 / 5.0)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6), m=st.integers(1, 4))
def test_joseph_equals_standard_and_information_form(seed, n, m):
    # For the optimal gain the Joseph form equals (I - KH)P (Bar-Shalom et al. 2001 §5.2.3)
    # and the information form P⁺⁻¹ = P⁻¹ + Hᵀ R⁻¹ H, x⁺ = P⁺(P⁻¹x + Hᵀ R⁻¹ y)
    # (the information filter, an independent re-derivation; Simon 2006, Optimal State
    # Estimation, information filtering).
    rng = np.random.default_rng(seed)
    P = random_spd(rng, n)
    R = random_spd(rng, m, 0.3)
    H = rng.standard_normal((m, n))
    x = rng.standard_normal(n)
    y = rng.standard_normal(m)
    xj, Pj, ij = joseph_update(x, P, y, H, R)
    xs, Ps, is_ = standard_update(x, P, y, H, R)
    assert ij.ok and is_
    Pinf = np.linalg.inv(np.linalg.inv(P) + H.T @ np.linalg.solve(R, H))
    xinf = Pinf @ (np.linalg.solve(P, x) + H.T @ np.linalg.solve(R, y))
    scale = np.abs(P).max()
    np.testing.assert_allclose(Pj, Ps, atol=1e-10 * scale)
    np.testing.assert_allclose(Pj, Pinf, atol=1e-9 * scale)
    np.testing.assert_allclose(xj, xinf, atol=1e-9 * (1 + np.abs(xinf).max()))
    np.testing.assert_array_equal(Pj, Pj.T)
    nu = y - H @ x
    assert ij.nis == pytest.approx(nu @ np.linalg.solve(H @ P @ H.T + R, nu), rel=1e-9)


def test_nonlinear_h_argument_is_used():
    rng = np.random.default_rng(3)
    P = random_spd(rng, 3)
    H = rng.standard_normal((2, 3))
    x = rng.standard_normal(3)
    h = np.array([0.3, -0.2])
    y = np.array([1.0, 2.0])
    x1, _, info = joseph_update(x, P, y, H, np.eye(2), h=h)
    np.testing.assert_allclose(info.innovation, y - h)
    np.testing.assert_allclose(x1, x + info.gain @ (y - h))


def test_consider_update_schmidt_formulas():
    # Schmidt-Kalman consider filter (Woodbury & Junkins 2010; O'Keefe 2015 §3.2.2):
    # with s estimated and c considered, K_s = (P_ss H_sᵀ + P_sc H_cᵀ) S⁻¹, K_c = 0,
    # P_ss⁺ = P_ss − K_s S K_sᵀ, P_sc⁺ = P_sc − K_s H P_{·c}, P_cc⁺ = P_cc, x_c⁺ = x_c.
    rng = np.random.default_rng(11)
    n, m = 5, 2
    P = random_spd(rng, n)
    H = rng.standard_normal((m, n))
    R = random_spd(rng, m, 0.2)
    x = rng.standard_normal(n)
    y = rng.standard_normal(m)
    c = np.array([False, False, False, True, True])
    s = ~c
    xp, Pp, info = consider_update(x, P, y, H, R, consider=[3, 4])
    assert info.ok
    S = H @ P @ H.T + R
    Ks = P[s] @ H.T @ np.linalg.inv(S)
    np.testing.assert_allclose(xp[c], x[c], rtol=0, atol=0)
    np.testing.assert_allclose(xp[s], x[s] + Ks @ (y - H @ x), atol=1e-12)
    np.testing.assert_allclose(Pp[np.ix_(s, s)], P[np.ix_(s, s)] - Ks @ S @ Ks.T, atol=1e-10)
    np.testing.assert_allclose(Pp[np.ix_(c, c)], P[np.ix_(c, c)], atol=1e-12)
    np.testing.assert_allclose(Pp[np.ix_(s, c)], P[np.ix_(s, c)] - Ks @ H @ P[:, c],
                               atol=1e-10)
    # the boolean-mask spelling gives the same answer
    xb, Pb, _ = joseph_update(x, P, y, H, R, consider=c)
    np.testing.assert_array_equal(xb, xp)
    np.testing.assert_array_equal(Pb, Pp)
    # considering states keeps more uncertainty than estimating them (trace is larger)
    _, Pfull, _ = joseph_update(x, P, y, H, R)
    assert np.trace(Pp[np.ix_(s, s)]) >= np.trace(Pfull[np.ix_(s, s)]) - 1e-12


def test_failed_factorisation_leaves_prior_unchanged():
    x = np.array([1.0, 2.0])
    P = np.eye(2)
    # R = -2 makes S = 1 - 2 < 0: not positive definite
    x1, P1, info = joseph_update(x, P, 0.5, [1.0, 0.0], -2.0)
    assert not info.ok
    assert "positive definite" in info.reason
    np.testing.assert_array_equal(x1, x)
    np.testing.assert_array_equal(P1, P)
    assert x1 is not x and P1 is not P
    assert np.isnan(info.nis) and info.gain is None
    # NaN measurement: refused, not propagated into the state
    x2, P2, info2 = joseph_update(x, P, np.nan, [1.0, 0.0], 1.0)
    assert not info2.ok and "non-finite" in info2.reason
    np.testing.assert_array_equal(x2, x)
    np.testing.assert_array_equal(P2, P)


def test_shape_errors_are_value_errors():
    with pytest.raises(ValueError, match="P must have shape"):
        joseph_update([0.0, 0.0], np.eye(3), 1.0, [1.0, 0.0], 1.0)
    with pytest.raises(ValueError, match="H must have shape"):
        joseph_update([0.0, 0.0], np.eye(2), 1.0, [1.0, 0.0, 0.0], 1.0)
    with pytest.raises(ValueError, match="consider indices"):
        joseph_update([0.0, 0.0], np.eye(2), 1.0, [1.0, 0.0], 1.0, consider=[5])


def test_safe_cholesky():
    rng = np.random.default_rng(0)
    A = random_spd(rng, 4)
    L, ok = safe_cholesky(A)
    assert ok
    np.testing.assert_allclose(L @ L.T, A, atol=1e-12)
    assert np.allclose(L, np.tril(L))
    assert safe_cholesky(np.diag([1.0, -1.0])) == (None, False)
    assert safe_cholesky(np.diag([1.0, 0.0])) == (None, False)  # singular: zero pivot
    assert safe_cholesky(np.array([[1.0, np.nan], [np.nan, 1.0]])) == (None, False)
    with pytest.raises(ValueError):
        safe_cholesky(np.ones(3))


def test_kf_predict_matches_explicit_formula():
    rng = np.random.default_rng(5)
    F = rng.standard_normal((4, 4))
    P = random_spd(rng, 4)
    G = rng.standard_normal((4, 2))
    Q = random_spd(rng, 2)
    x = rng.standard_normal(4)
    xp, Pp = kf_predict(x, P, F, Q, G=G)
    np.testing.assert_allclose(xp, F @ x)
    np.testing.assert_allclose(Pp, F @ P @ F.T + G @ Q @ G.T, atol=1e-12)
    np.testing.assert_array_equal(Pp, Pp.T)
    B = rng.standard_normal((4, 1))
    xp2, _ = kf_predict(x, P, F, np.eye(4), u=[2.0], B=B)
    np.testing.assert_allclose(xp2, F @ x + 2.0 * B[:, 0])
    np.testing.assert_array_equal(symmetrize([[1.0, 2.0], [0.0, 1.0]]), [[1, 1], [1, 1]])


def test_cholesky_nb_matches_numpy_and_flags_failure():
    rng = np.random.default_rng(2)
    A = random_spd(rng, 5)
    L, ok = cholesky_nb(A)
    assert ok
    np.testing.assert_allclose(L, np.linalg.cholesky(A), atol=1e-12)
    L2, ok2 = cholesky_nb(np.diag([1.0, -3.0, 1.0]))
    assert not ok2 and np.all(L2 == 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_joseph_update_nb_matches_object_layer(seed):
    rng = np.random.default_rng(seed)
    n, m = 6, 3
    P = random_spd(rng, n)
    H = rng.standard_normal((m, n))
    R = random_spd(rng, m, 0.5)
    x = rng.standard_normal(n)
    y = rng.standard_normal(m)
    mask = np.zeros(n, dtype=np.bool_)
    mask[4:] = seed > 0
    xr, Pr, info = joseph_update(x, P, y, H, R, consider=mask)
    xn, Pn, nis_, ok = joseph_update_nb(x, P, y - H @ x, H, R, mask)
    assert ok
    np.testing.assert_allclose(xn, xr, atol=1e-11)
    np.testing.assert_allclose(Pn, Pr, atol=1e-10)
    assert nis_ == pytest.approx(info.nis, rel=1e-10)
    # failure path of the kernel: S not positive definite → prior returned, ok False
    xf, Pf, nf, okf = joseph_update_nb(x, P, y - H @ x, H, -1e3 * np.eye(m), mask)
    assert not okf and np.isnan(nf)
    np.testing.assert_array_equal(xf, x)
    np.testing.assert_array_equal(Pf, P)
