"""The vectorised observation geometry; the thesis LEO case is unlit (Bernard 2021 §9.3)."""

import warnings

import numpy as np
import pytest

from lightcurve.geometry import observation as ob
from lightcurve.geometry.orbits import Orbit, orbit_from_section
from lightcurve.geometry.schedules import bernard_switching_schedule
from lightcurve.geometry.sites import get_site, site_position_gcrs
from lightcurve.geometry.time import ephemeris, skyfield_times
from lightcurve.geometry.visibility import (UnlitPassWarning, airmass_kasten_young,
                                            check_illumination)

# Bernard (2021) LEO test orbit (§9.3): a = 6871.14 km, e = 0.01, i = 83°, Ω = ω = 0,
# ν = 126.264° at 2020-03-01 08:08:40 UTC, observed for 360 s from Socorro and Bear Lake
EPOCH = "2020-03-01T08:08:40Z"
LEO = {"type": "keplerian", "a_km": 6871.14, "e": 0.01, "i_deg": 83.0, "raan_deg": 0.0,
       "argp_deg": 0.0, "nu_deg": 126.264}


@pytest.fixture(scope="module")
def leo_pass():
    t = np.arange(0.0, 361.0, 5.0)
    r, v = orbit_from_section(LEO).positions(EPOCH, t)
    return t, r, v


def test_thesis_leo_above_horizon_but_in_umbra(leo_pass):
    t, r, v = leo_pass
    for sid in ("socorro", "bear_lake"):
        g = ob.compute_geometry(EPOCH, t, 0, [sid], r, v)
        assert np.all(g.above_horizon), sid
        assert np.all(g.site_dark), sid
        assert np.all(g.lit_fraction == 0.0), sid            # conical umbra, whole window
        assert not np.any(g.visible)
        gc = ob.compute_geometry(EPOCH, t, 0, [sid], r, v, eclipse_model="cylindrical")
        assert np.all(gc.lit_fraction == 0.0)
    # two-site switching schedule over the same pass
    ts, si = bernard_switching_schedule(duration_s=360.0)
    r2, v2 = orbit_from_section(LEO).positions(EPOCH, ts)
    g = ob.compute_geometry(EPOCH, ts, si, ["socorro", "bear_lake"], r2, v2)
    assert np.all(g.above_horizon) and np.all(g.lit_fraction == 0)
    with pytest.warns(UnlitPassWarning, match="WHOLE pass"):
        lit = g.check_illumination()
    assert np.all(lit == 0)
    with pytest.warns(UnlitPassWarning, match="ignore_eclipse=True"):
        lit = check_illumination(g, ignore_eclipse=True)
    assert np.all(lit == 1)


def test_geometry_against_independent_computation(leo_pass):
    from skyfield.api import wgs84

    t, r, v = leo_pass
    si = (np.arange(t.size) % 2).astype(int)
    sites = [get_site("socorro"), get_site("bear_lake")]
    g = ob.compute_geometry(EPOCH, t, si, sites, r, v)
    eph = ephemeris()
    times = skyfield_times(EPOCH, t)
    for k, site in enumerate(sites):
        m = si == k
        # site positions: skyfield oracle, 1e-6 relative
        ref = site_position_gcrs(site, EPOCH, t[m])
        assert np.max(np.linalg.norm(g.r_site_eci_m[m] - ref, axis=1)
                      / np.linalg.norm(ref, axis=1)) < 1e-6
        topos = wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.height_m)
        # object altitude/azimuth: skyfield's altaz of the GCRS difference vector
        rot = np.moveaxis(topos.rotation_at(times), -1, 0)[m]
        loc = np.einsum("nij,nj->ni", rot, r[m] - ref)
        alt = np.arcsin(loc[:, 2] / np.linalg.norm(loc, axis=1))
        np.testing.assert_allclose(g.elevation_rad[m], alt, atol=1e-9)
        # Sun altitude at the site: skyfield topocentric observation (differs from ours only
        # by the topocentric light time, << 1e-6 rad)
        # (astrometric, i.e. without aberration, like ours; rotated into skyfield's horizon frame)
        sun_top = (eph["earth"] + topos).at(times[m]).observe(eph["sun"]).position.m.T
        sl = np.einsum("nij,nj->ni", rot, sun_top)
        sun_alt = np.arcsin(sl[:, 2] / np.linalg.norm(sl, axis=1))
        np.testing.assert_allclose(g.sun_elevation_rad[m], sun_alt, atol=1e-6)
    # phase angle and ranges, recomputed inline
    to_sun = g.r_sun_eci_m - r
    to_obs = g.r_site_eci_m - r
    cosph = np.sum(to_sun * to_obs, 1) / np.linalg.norm(to_sun, axis=1) / np.linalg.norm(to_obs, axis=1)
    np.testing.assert_allclose(np.cos(g.phase_angle_rad), cosph, atol=1e-12)
    np.testing.assert_allclose(g.range_obs_m, np.linalg.norm(to_obs, axis=1))
    np.testing.assert_allclose(np.linalg.norm(g.obj_to_sun_unit, axis=1), 1.0)
    sub = g.subset(si == 1)
    assert len(sub) == (si == 1).sum() and np.all(sub.site_index == 1)
    summ = g.summary()
    assert summ["socorro"]["n_epochs"] + summ["bear_lake"]["n_epochs"] == t.size


def test_airmass_kasten_young():
    # Kasten & Young (1989): the rigorous air mass is 1 at the zenith, ≈ 1.994 at 30° and
    # 38.0868 at the horizon; their formula stays within 0.5 % of it (37.92 at 0°). Hand
    # evaluation of the formula: X(90°) = 1/(1 + 0.50572·96.07995^-1.6364) = 0.99971.
    x = airmass_kasten_young(np.radians([90.0, 30.0, 0.0, -1.0]))
    np.testing.assert_allclose(x[:3], [1.0, 1.9942, 38.0868], rtol=5e-3)
    assert abs(x[0] - 0.99971) < 1e-5 and abs(x[2] - 37.9196) < 1e-3
    assert np.isnan(x[3])


def test_sunlit_pass_no_warning_and_visible():
    # a sun-synchronous-like dawn/dusk orbit seen at twilight: find epochs that are visible
    t = np.arange(0.0, 6000.0, 20.0)
    orb = Orbit.from_elements(7000e3, 0.001, np.radians(98), np.radians(250), 0.0, 0.0)
    r, v = orb.positions("2020-06-21T03:00:00Z", t)
    g = ob.compute_geometry("2020-06-21T03:00:00Z", t, 0, ["bear_lake"], r, v)
    np.testing.assert_array_equal(g.visible, g.above_horizon & g.site_dark & (g.lit_fraction > 0))
    lit = g.subset(g.lit_fraction == 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.all(lit.check_illumination() == 1.0)


def test_bad_arguments(leo_pass):
    t, r, v = leo_pass
    with pytest.raises(ValueError, match="site_index out of range"):
        ob.compute_geometry(EPOCH, t, 2, ["socorro"], r)
    with pytest.raises(ValueError, match="r_obj_eci_m"):
        ob.compute_geometry(EPOCH, t, 0, ["socorro"], r[:-1])
    from lightcurve.errors import InputError
    with pytest.raises(InputError, match="unknown site"):
        ob.compute_geometry(EPOCH, t, 0, ["atlantis"], r)


def test_horizon_mask_blocks(leo_pass):
    t, r, v = leo_pass
    base = get_site("bear_lake")
    masked = {"id": "bl_masked", "lat_deg": base.lat_deg, "lon_deg": base.lon_deg,
              "height_m": base.height_m,
              "horizon_mask": {"az_deg": [0.0, 180.0], "alt_deg": [40.0, 40.0]}}
    g0 = ob.compute_geometry(EPOCH, t, 0, [base], r, v)
    g1 = ob.compute_geometry(EPOCH, t, 0, [masked], r, v)
    np.testing.assert_allclose(g1.elevation_rad, g0.elevation_rad)
    np.testing.assert_array_equal(g1.above_horizon, g0.elevation_rad > np.radians(40.0))
    assert 0 < g1.above_horizon.sum() < t.size   # the pass peaks at 65°, starts at 17°
