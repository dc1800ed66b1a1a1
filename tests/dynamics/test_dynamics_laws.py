"""Attitude laws (lightcurve.dynamics.laws): the Starlink nadir/Sun-yaw law and body rates.

Oracles: the ellipsoid's own geometry (the geodetic normal through a point is the gradient of
x²/a² + y²/a² + z²/b² at its foot point on the ellipsoid), orthonormality, and a constant-rate
rotation built with rotvec_to_quat (q(t) = exp(ω t) ⊗ q0, the body-frame increment).
"""

from __future__ import annotations

import numpy as np
import pytest

from lightcurve.dynamics.laws import LAWS, attitude_law, geodetic_up_itrs, law_body_rates, nadir_sun_yaw_dcm
from lightcurve.geometry.frames import itrs_rotation
from lightcurve.geometry.orbits import geodetic_height_m, kepler_propagate
from lightcurve.geometry.sites import WGS84_A_M, WGS84_F
from lightcurve.geometry.time import sun_position_gcrs
from lightcurve.rotations import quat_mult, quat_rotate, quat_rotate_inv, quat_to_dcm, rotvec_to_quat

EPOCH = "2022-03-01T03:00:00Z"


def _orbit(n=41, span=900.0):
    t = np.linspace(0.0, span, n)
    r0 = np.array([6928e3, 0.0, 0.0])
    v0 = 7584.0 * np.array([0.0, np.cos(0.93), np.sin(0.93)])  # 53° inclination (Starlink shell)
    r, _ = kepler_propagate(r0, v0, t)
    return t, r, sun_position_gcrs(EPOCH, t)


def test_geodetic_up_is_the_ellipsoid_normal_at_the_foot_point():
    rng = np.random.default_rng(1)
    u = rng.normal(size=(200, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    p = u * rng.uniform(6.4e6, 4.3e7, size=(200, 1))
    up = geodetic_up_itrs(p)
    h = geodetic_height_m(p)
    foot = p - h[:, None] * up
    b = WGS84_A_M * (1 - WGS84_F)
    on = (foot[:, 0] ** 2 + foot[:, 1] ** 2) / WGS84_A_M**2 + foot[:, 2] ** 2 / b**2
    np.testing.assert_allclose(on, 1.0, atol=1e-9)            # foot point on the ellipsoid
    g = foot / np.array([WGS84_A_M**2, WGS84_A_M**2, b**2])
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    np.testing.assert_allclose(up, g, atol=1e-9)              # normal there = up


def test_nadir_sun_yaw_axes():
    t, r, rs = _orbit()
    q = attitude_law("nadir_sun_yaw", r, rs, EPOCH, t)
    A = quat_to_dcm(q)
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", A, A), np.broadcast_to(np.eye(3), A.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(A), 1.0, atol=1e-12)
    x, y, z = (quat_rotate_inv(q, e) for e in np.eye(3))      # body axes in ECI
    # +Z = geodetic nadir (independent: up at the sub-point in ITRS, rotated back)
    R = itrs_rotation(EPOCH, t, exact=True)
    up = np.einsum("nji,nj->ni", R, geodetic_up_itrs(np.einsum("nij,nj->ni", R, r)))
    np.testing.assert_allclose(z, -up, atol=1e-9)
    # +X horizontal, in the (Z, Sun) plane, on the Sun's side
    s = rs - r
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    np.testing.assert_allclose(np.sum(x * z, 1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(np.cross(z, s) * x, 1), 0.0, atol=1e-12)
    assert np.all(np.sum(x * s, 1) > 0)
    # geocentric variant: +Z = −r̂; the two differ by less than 0.2° (geodetic − geocentric latitude)
    qg = attitude_law("nadir_sun_yaw_geocentric", r, rs, EPOCH, t)
    zg = quat_rotate_inv(qg, np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(zg, -r / np.linalg.norm(r, axis=1, keepdims=True), atol=1e-12)
    ang = np.degrees(np.arccos(np.clip(np.sum(zg * z, 1), -1, 1)))
    assert 0.0 < ang.max() < 0.2
    # quaternion signs continuous (no jumps between samples)
    assert np.all(np.sum(q[1:] * q[:-1], 1) > 0)
    # chassis (+Z facet) sees the Sun when the Sun is below the local horizontal, array (+X) always
    s_b = quat_rotate(q, s)
    assert np.all(s_b[:, 0] >= 0) and np.allclose(s_b[:, 1], 0.0, atol=1e-12)


def test_degenerate_sun_on_the_z_axis_still_gives_a_frame():
    A = nadir_sun_yaw_dcm(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, -5.0]]))
    np.testing.assert_allclose(A[0] @ A[0].T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(A[0][2], [0.0, 0.0, 1.0])


def test_law_body_rates_recover_a_constant_rate():
    w = np.array([0.01, -0.02, 0.005])       # rad/s, body axes
    t = np.sort(np.random.default_rng(2).uniform(0, 100, 50))
    q0 = rotvec_to_quat(np.array([0.3, -0.2, 1.0]))
    q = quat_mult(rotvec_to_quat(t[:, None] * w), np.broadcast_to(q0, (50, 4)))
    np.testing.assert_allclose(law_body_rates(q, t), np.broadcast_to(w, (50, 3)), atol=1e-10)
    np.testing.assert_allclose(law_body_rates(q[:1], t[:1]), 0.0)


def test_law_body_rates_of_the_orbit_law_are_close_to_the_orbit_rate():
    """Nadir pointing turns at the orbit rate n about the body y axis (to the yaw correction)."""
    t, r, rs = _orbit(n=91)
    q = attitude_law("nadir_sun_yaw_geocentric", r, rs, EPOCH, t)
    w = law_body_rates(q, t)
    n = 7584.0 / 6928e3
    # the orbit normal in body axes is the rotation axis of the nadir frame: |ω·ĥ| ≈ n
    h = np.cross(r[:-1], r[1:])
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    hb = quat_rotate(q[:-1], h)
    assert np.allclose(np.abs(np.sum(w[:-1] * hb, 1)), n, rtol=0.02)


def test_errors():
    t, r, rs = _orbit(n=3)
    with pytest.raises(ValueError, match="unknown attitude law"):
        attitude_law("sun_pointing", r, rs, EPOCH, t)
    with pytest.raises(ValueError, match="must be"):
        attitude_law("nadir_sun_yaw", r, rs[:2], EPOCH, t)
    assert "nadir_sun_yaw" in LAWS
