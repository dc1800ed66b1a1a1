"""Earth shadow: conical umbra/penumbra against an independent ray-traced solar disc."""

import numpy as np
import pytest

from lightcurve.geometry import eclipse as ec
from lightcurve.geometry.time import AU_M, sun_position_gcrs

RE = ec.R_EARTH_SHADOW_M


def _raytraced_fraction(r, s, n=400):
    """Independent oracle: sample the solar disc (uniform grid over the sphere's projected
    disc, as seen from r) and test each ray r → point for intersection with the Earth ball."""
    d = s - r
    dist = np.linalg.norm(d)
    w = d / dist
    u = np.cross(w, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    vv = np.cross(w, u)
    g = (np.arange(n) + 0.5) / n * 2 - 1
    X, Y = np.meshgrid(g, g)
    inside = X ** 2 + Y ** 2 <= 1
    pts = s + ec.R_SUN_M * (X[inside, None] * u + Y[inside, None] * vv)   # disc points
    dirs = pts - r
    L = np.linalg.norm(dirs, axis=1)
    dirs /= L[:, None]
    # ray-sphere: closest approach of the ray to the Earth's centre, ahead of r
    tca = -(dirs @ r)
    dmin2 = r @ r - tca ** 2
    blocked = (tca > 0) & (dmin2 < RE ** 2)
    return 1 - blocked.mean()


def test_simple_lit_and_umbra():
    s = np.array([AU_M, 0, 0])
    r = np.array([[-(RE + 500e3), 0, 0], [RE + 500e3, 0, 0], [-(RE + 500e3), 0, RE + 2000e3]])
    for model in ("conical", "cylindrical"):
        np.testing.assert_array_equal(ec.lit_fraction(r, s, model), [0.0, 1.0, 1.0])
    np.testing.assert_array_equal(ec.shadow_region(r, s), [ec.UMBRA, ec.LIT, ec.LIT])


def test_penumbra_matches_raytrace():
    s = np.array([AU_M, 0, 0])
    # LEO at 7000 km behind the Earth: the penumbra is a thin shell near z ≈ R⊕; scan across it
    zs = np.linspace(RE - 80e3, RE + 80e3, 41)
    r = np.stack([np.full_like(zs, -7000e3 * np.sqrt(1 - (RE / 7000e3) ** 2)),
                  np.zeros_like(zs), zs], -1)
    f = ec.lit_fraction(r, s)
    assert f[0] == 0.0 and f[-1] == 1.0
    assert np.all(np.diff(f) >= -1e-12)
    mid = (f > 0.02) & (f < 0.98)
    assert mid.sum() >= 5
    for k in np.flatnonzero(mid)[::2]:
        assert abs(f[k] - _raytraced_fraction(r[k], s)) < 0.01
    # GEO distance: much wider penumbra, same oracle
    r = np.array([-42164e3 * np.cos(0.1505), 0.0, 42164e3 * np.sin(0.1505)])
    fk = ec.lit_fraction(r, s)[0]
    assert 0.05 < fk < 0.95
    assert abs(fk - _raytraced_fraction(r, s)) < 0.01
    codes = ec.shadow_region(r, s)
    assert codes[0] == ec.PENUMBRA


def test_antumbra_beyond_the_umbra_tip():
    # umbra length ≈ R⊕ d☉/(R☉ − R⊕) ≈ 1.38e9 m; at 3e9 m behind the Earth the Earth is a
    # small disc inside the Sun's (annular): fraction 1 − (b/a)²
    s = np.array([AU_M, 0, 0])
    r = np.array([-3e9, 0.0, 0.0])
    a = np.arcsin(ec.R_SUN_M / np.linalg.norm(s - r))
    b = np.arcsin(RE / 3e9)
    assert ec.shadow_region(r, s)[0] == ec.ANTUMBRA
    assert abs(ec.lit_fraction(r, s)[0] - (1 - (b / a) ** 2)) < 1e-12
    assert abs(ec.lit_fraction(r, s)[0] - _raytraced_fraction(r, s, n=800)) < 0.01


def test_geo_eclipse_seasons():
    """GEO satellites are eclipsed around local midnight only near the equinoxes
    (Earth's shadow is ±8.7° wide at GEO, the Sun's declination reaches 23.4°)."""
    a = 42164e3
    for epoch, expect_umbra in (("2020-03-20T12:00:00Z", True), ("2020-06-21T12:00:00Z", False)):
        s = sun_position_gcrs(epoch, [0.0])[0]
        shat = s / np.linalg.norm(s)
        # equatorial GEO point opposite the Sun's right ascension (local midnight)
        ra = np.arctan2(shat[1], shat[0]) + np.pi
        r = a * np.array([np.cos(ra), np.sin(ra), 0.0])
        f = ec.lit_fraction(r, s)[0]
        assert (f == 0.0) == expect_umbra
        assert (ec.lit_fraction(r, s, "cylindrical")[0] == 0.0) == expect_umbra


def test_bad_input():
    with pytest.raises(ValueError, match="inside the Earth"):
        ec.lit_fraction([1e6, 0, 0], [AU_M, 0, 0])
    with pytest.raises(ValueError, match="unknown shadow model"):
        ec.lit_fraction([1e7, 0, 0], [AU_M, 0, 0], model="flat")
