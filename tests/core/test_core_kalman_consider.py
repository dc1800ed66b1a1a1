"""The block-form Schmidt consider update (lightcurve.core.kalman.consider_update_nb, O'Keefe
2015 eq. 3.47–3.52) against the same update written here in plain NumPy on the augmented state
``[x, β]`` (gain rows of β zeroed, Joseph form; Woodbury & Junkins 2010)."""

import numpy as np

from lightcurve.core import kalman as K

RNG = np.random.default_rng(17)


def _joint(n, p):
    A = RNG.normal(size=(n + p, n + p))
    return A @ A.T + (n + p) * np.eye(n + p)


def _augmented_oracle(x, Pa, nu, H, J, R):
    """Schmidt update of [x, β] with H_aug = [H, J]: K_aug = [P_x· H_augᵀ W⁻¹; 0]."""
    n = x.size
    Ha = np.hstack([H, J])
    W = Ha @ Pa @ Ha.T + R
    Ka = Pa @ Ha.T @ np.linalg.inv(W)
    Ka[n:] = 0.0
    IKH = np.eye(Pa.shape[0]) - Ka @ Ha
    Pn = IKH @ Pa @ IKH.T + Ka @ R @ Ka.T
    return x + Ka[:n] @ nu, Pn, nu @ np.linalg.solve(W, nu), W, Ka[:n]


def test_consider_update_matches_the_augmented_joseph_update():
    for n, p, m in ((3, 0, 2), (3, 3, 4), (3, 38, 8), (6, 5, 1)):
        Pa = _joint(n, p)
        x = RNG.normal(size=n)
        nu = RNG.normal(size=m)
        H = RNG.normal(size=(m, n))
        J = RNG.normal(size=(m, p))
        R = np.diag(RNG.uniform(0.5, 2.0, m))
        P, C, B = Pa[:n, :n].copy(), Pa[:n, n:].copy(), Pa[n:, n:].copy()
        xo, Po, niso, W, Kx = _augmented_oracle(x, Pa, nu, H, J, R)
        for joseph in (True, False):
            xn, Pn, Cn, nis, ok = K.consider_update_nb(x, P, C, B, nu, H, J, R, joseph)
            assert ok
            np.testing.assert_allclose(xn, xo, rtol=1e-11, atol=1e-12)
            np.testing.assert_allclose(Pn, Po[:n, :n], rtol=1e-9, atol=1e-11)
            np.testing.assert_allclose(Cn, Po[:n, n:], rtol=1e-9, atol=1e-11)
            np.testing.assert_allclose(Po[n:, n:], B)          # β's covariance unchanged
            assert nis == np.float64(niso) or abs(nis - niso) < 1e-10 * niso
        # eq. 3.52 as printed: P⁺ = P − K W Kᵀ, L⁺ = (I − KH) L − K J B
        np.testing.assert_allclose(
            K.consider_update_nb(x, P, C, B, nu, H, J, R, False)[1], P - Kx @ W @ Kx.T,
            rtol=1e-9, atol=1e-11)
        np.testing.assert_allclose(
            K.consider_update_nb(x, P, C, B, nu, H, J, R, False)[2],
            (np.eye(n) - Kx @ H) @ C - Kx @ J @ B, rtol=1e-9, atol=1e-11)


def test_consider_update_without_consider_parameters_is_the_joseph_update():
    n, m = 4, 3
    P = _joint(n, 0)
    x = RNG.normal(size=n)
    nu = RNG.normal(size=m)
    H = RNG.normal(size=(m, n))
    R = np.eye(m) * 0.7
    xa, Pa, nisa, oka = K.joseph_update_nb(x, P, nu, H, R, np.zeros(n, dtype=np.bool_))
    xb, Pb, Cb, nisb, okb = K.consider_update_nb(x, P, np.zeros((n, 0)), np.zeros((0, 0)), nu,
                                                 H, np.zeros((m, 0)), R, True)
    assert oka and okb and Cb.shape == (n, 0)
    np.testing.assert_allclose(xb, xa, rtol=1e-13)
    np.testing.assert_allclose(Pb, Pa, rtol=1e-12, atol=1e-14)
    assert abs(nisb - nisa) < 1e-12 * nisa


def test_consider_update_refuses_and_keeps_the_prior():
    n, p, m = 3, 2, 2
    Pa = _joint(n, p)
    P, C, B = Pa[:n, :n], Pa[:n, n:], Pa[n:, n:]
    H = RNG.normal(size=(m, n))
    J = RNG.normal(size=(m, p))
    x = np.ones(n)
    for nu, R in ((np.array([np.nan, 0.0]), np.eye(m)),            # non-finite innovation
                  (np.zeros(m), -100.0 * np.eye(m))):               # W not positive definite
        xn, Pn, Cn, nis, ok = K.consider_update_nb(x, P, C, B, nu, H, J, R, True)
        assert not ok and np.isnan(nis)
        assert np.array_equal(xn, x) and np.array_equal(Pn, P) and np.array_equal(Cn, C)
