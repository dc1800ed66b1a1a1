"""Frames: GCRS<->ITRS, alt/az (skyfield oracle), LVLH/nadir/RSW axes."""

import numpy as np

from lightcurve.geometry import frames as fr
from lightcurve.geometry.orbits import coe_to_rv
from lightcurve.geometry.sites import get_site
from lightcurve.geometry.time import skyfield_times, timescale

# ISS TLE from the skyfield documentation (valid checksums)
L1 = "1 25544U 98067A   14020.93268519  .00009878  00000-0  18200-3 0  5082"
L2 = "2 25544  51.6498 109.4756 0003572  55.9686 274.8005 15.49815350868473"
TLE_EPOCH = "2014-01-20T22:23:04Z"


def test_gcrs_itrs_against_skyfield_frame_xyz():
    from skyfield.api import EarthSatellite
    from skyfield.framelib import itrs

    sat = EarthSatellite(L1, L2, ts=timescale())
    t_s = np.linspace(0, 3000, 11)
    t = skyfield_times(TLE_EPOCH, t_s)
    p = sat.at(t)
    r = p.position.m.T
    ref = p.frame_xyz(itrs).m.T
    mine = fr.gcrs_to_itrs(r, TLE_EPOCH, t_s)
    assert np.max(np.linalg.norm(mine - ref, axis=1)) < 1e-6
    np.testing.assert_allclose(fr.itrs_to_gcrs(mine, TLE_EPOCH, t_s), r, atol=1e-6)
    # velocities: skyfield's ITRS velocity of the same satellite
    _, v_ref = p.frame_xyz_and_velocity(itrs)
    _, v_mine = fr.gcrs_to_itrs_state(r, p.velocity.m_per_s.T, TLE_EPOCH, t_s)
    np.testing.assert_allclose(v_mine, v_ref.m_per_s.T, atol=1e-3)
    r2, v2 = fr.itrs_to_gcrs_state(mine, v_mine, TLE_EPOCH, t_s)
    np.testing.assert_allclose(v2, p.velocity.m_per_s.T, atol=1e-6)


def test_altaz_matches_skyfield():
    from skyfield.api import EarthSatellite, wgs84

    sat = EarthSatellite(L1, L2, ts=timescale())
    site = get_site("socorro")
    topos = wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.height_m)
    t_s = np.linspace(0, 5400, 37)
    t = skyfield_times(TLE_EPOCH, t_s)
    r = sat.at(t).position.m.T
    alt, az, rng = fr.altaz(site, r, TLE_EPOCH, t_s)
    a_ref, z_ref, d_ref = (sat - topos).at(t).altaz()
    np.testing.assert_allclose(alt, a_ref.radians, atol=1e-8)
    dz = np.angle(np.exp(1j * (az - z_ref.radians)))
    assert np.max(np.abs(dz * np.cos(alt))) < 1e-8
    np.testing.assert_allclose(rng, d_ref.m, rtol=1e-9)
    # round trip through the ENU helpers
    enu = fr.altaz_to_enu(alt, az) * rng[:, None]
    np.testing.assert_allclose(enu, fr.topocentric_enu(site, r, TLE_EPOCH, t_s), atol=1e-5)


def test_orbit_frames_axes():
    r, v = coe_to_rv(7000e3, 0.0, np.radians(50), 0.3, 0.0, np.radians([10, 100, 250]))
    C = fr.lvlh_dcm(r, v)
    for c, ri, vi in zip(C, r, v):
        np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-12)
        assert abs(np.linalg.det(c) - 1) < 1e-12
        np.testing.assert_allclose(c[2], -ri / np.linalg.norm(ri), atol=1e-12)      # nadir
        np.testing.assert_allclose(c[0], vi / np.linalg.norm(vi), atol=1e-12)       # circular
        h = np.cross(ri, vi)
        np.testing.assert_allclose(c[1], -h / np.linalg.norm(h), atol=1e-12)
        # passive: the nadir vector expressed in the frame is +z
        np.testing.assert_allclose(c @ (-ri), [0, 0, np.linalg.norm(ri)], atol=1e-6)
    np.testing.assert_allclose(fr.nadir_dcm(r, v), C)
    W = fr.rsw_dcm(r, v)
    np.testing.assert_allclose(W[:, 0], -C[:, 2], atol=1e-12)   # R = -nadir
    np.testing.assert_allclose(W[:, 2], -C[:, 1], atol=1e-12)   # W = -o2
    np.testing.assert_allclose(W[:, 1], C[:, 0], atol=1e-12)    # S = along-track


def test_earth_pole_precession():
    # the CIP drifts from GCRS z by precession (~20"/yr in declination) plus nutation: in 2020
    # about 0.11 deg (IERS Conventions 2010, precession rate 2004.19"/century in declination)
    k = fr.earth_pole_gcrs("2020-03-01T00:00:00Z", [0.0])[0]
    ang = np.degrees(np.arccos(k[2]))
    assert 0.08 < ang < 0.15
    k0 = fr.earth_pole_gcrs("2000-01-01T12:00:00Z", [0.0])[0]
    assert np.degrees(np.arccos(k0[2])) < 0.01


def test_interpolated_rotation_matches_exact():
    # >64 epochs use hourly nodes for precession-nutation; the documented bound is 1e-10 rad
    t = skyfield_times("2020-03-01T08:08:40Z", np.sort(np.r_[np.linspace(0, 2 * 86400, 500),
                                                              [1234.5, 99999.9]]))
    A = fr.itrs_rotation(t)
    B = fr.itrs_rotation(t, exact=True)
    assert np.abs(A - B).max() < 1e-10
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", A, A), np.broadcast_to(np.eye(3), A.shape),
                               atol=1e-10)
