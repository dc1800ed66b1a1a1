"""Single-point estimators WAVG (eq. 3.3), LSMN (eq. 3.9-3.10), WLSMN (eq. 3.12) and the
noise-free error maps of O'Keefe figs. 3.1-3.2."""

import numpy as np
import pytest

from lightcurve.css.configurations import cube, dual_pyramid
from lightcurve.css.single_point import angle_deg, error_map, estimate, lsmn_nb, wavg_nb


def _unit(v):
    return v / np.linalg.norm(v)


def test_wavg_matches_inline():
    css = dual_pyramid()
    rng = np.random.default_rng(0)
    for _ in range(50):
        s = _unit(rng.normal(size=3))
        y = css.signals(s)
        ref = (y[:, None] * css.normals).sum(axis=0)
        got = wavg_nb(y, css.normals, 0.0)
        if np.linalg.norm(ref) > 0:
            assert np.allclose(got, _unit(ref), atol=1e-14)


def test_lsmn_exact_when_three_independent_sensors():
    # noise-free cosine outputs y = H s are solved exactly by least squares when rank H = 3
    css = dual_pyramid(90.0)
    rng = np.random.default_rng(1)
    for _ in range(50):
        s = _unit(rng.normal(size=3))
        y = css.signals(s)
        for m in ("lsmn", "wlsmn"):
            assert angle_deg(estimate(m, y, css.normals), s) < 1e-6


def test_minimum_norm_branch_matches_inline_formula():
    # two active sensors: d = H^T (H H^T)^-1 y (eq. 3.10), then normalised
    normals = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    y = np.array([0.6, 0.3, 0.0])
    H = normals[:2]
    ref = _unit(H.T @ np.linalg.solve(H @ H.T, y[:2]))
    assert np.allclose(lsmn_nb(y, normals, 0.0, False), ref)
    # one active sensor: estimate is its normal
    assert np.allclose(estimate("lsmn", [0.0, 0.4, 0.0], normals), [0, 1, 0])
    # no active sensor: zeros
    assert np.all(estimate("wlsmn", [0.0, 0.0, 0.0], normals) == 0)


def test_wlsmn_weighted_solution_inline():
    css = dual_pyramid(90.0)
    rng = np.random.default_rng(5)
    s = _unit(np.array([0.2, 0.1, 0.9]))
    y = css.signals(s) + rng.normal(0, 0.02, 8)
    act = y > 0.1
    H, yy = css.normals[act], y[act]
    W = np.diag(yy)
    ref = _unit(np.linalg.solve(H.T @ W @ H, H.T @ W @ yy))
    assert np.allclose(estimate("wlsmn", y, css.normals, 0.1), ref, atol=1e-12)


def test_error_maps_figs_3_1_3_2():
    # With a 70 deg FOV the dual pyramid is partially underdetermined: LSMN is exact where
    # >= 3 sensors are active and wrong elsewhere; WAVG is biased nearly everywhere.
    em, fig = error_map(dual_pyramid(), "lsmn", n_az=73, n_el=37, plot=True)
    three = em.n_active >= 3
    assert em.error_deg[three].max() < 1e-5  # arccos resolution near 0
    assert em.error_deg[~three].max() > 10.0
    ew = error_map(dual_pyramid(), "wavg", n_az=73, n_el=37)
    assert np.median(ew.error_deg) > 5.0
    assert fig.axes and fig.axes[0].get_xlabel().startswith("Sun azimuth")
    import matplotlib.pyplot as plt
    plt.close(fig)
    # cube: along a face normal only one sensor sees the Sun, the estimate is exact there
    ec = error_map(cube(), "lsmn", n_az=9, n_el=5)
    assert ec.error_deg[2, 4] < 1e-5  # az 0, el 0 -> +x face


def test_unknown_method():
    with pytest.raises(ValueError):
        estimate("qmethod", np.ones(3), np.eye(3))
