"""Object positions reconstructed from topocentric alt/az + range or height."""

import csv

import numpy as np
import pytest

from lightcurve._paths import shared_data_dir
from lightcurve.errors import InputError
from lightcurve.geometry import frames as fr
from lightcurve.geometry import orbits as go
from lightcurve.geometry.sites import get_site
from lightcurve.geometry.time import skyfield_times

EPOCH = "2020-03-01T08:08:40Z"


def _truth():
    r0, v0 = go.coe_to_rv(6871.14e3, 0.01, np.radians(83), 0.0, 0.0, np.radians(126.264))
    t_s = np.linspace(0, 360, 13)
    r, _ = go.propagate_orbit(r0, v0, t_s, "point")
    return t_s, r


def test_roundtrip_range_and_height():
    from skyfield.api import wgs84
    from skyfield.positionlib import Geocentric

    site = get_site("bear_lake")
    t_s, r = _truth()
    t = skyfield_times(EPOCH, t_s)
    alt, az, rng = fr.altaz(site, r, EPOCH, t_s)
    back = go.positions_from_topocentric(site, t, np.degrees(alt), np.degrees(az), range_m=rng)
    assert np.max(np.linalg.norm(back - r, axis=1)) < 1e-4
    # heights from skyfield's own WGS84 inversion (oracle for geodetic_height_m)
    h_ref = wgs84.height_of(Geocentric(r.T / 149597870700.0, t=t)).m
    np.testing.assert_allclose(go.geodetic_height_m(fr.gcrs_to_itrs(r, EPOCH, t_s)), h_ref,
                               atol=1e-3)
    back_h = go.positions_from_topocentric(site, t, np.degrees(alt), np.degrees(az),
                                           height_m=h_ref)
    assert np.max(np.linalg.norm(back_h - r, axis=1)) < 0.05
    # ISO texts instead of a skyfield Time
    iso = [x.strftime("%Y-%m-%dT%H:%M:%S.%fZ") for x in t.utc_datetime()]
    back_iso = go.positions_from_topocentric(site, iso, np.degrees(alt), np.degrees(az),
                                             range_m=rng)
    assert np.max(np.linalg.norm(back_iso - r, axis=1)) < 1e-2


def test_topocentric_errors():
    site = get_site("maui")
    with pytest.raises(InputError, match="exactly one"):
        go.positions_from_topocentric(site, [EPOCH], [30.0], [10.0])
    with pytest.raises(InputError, match="does not reach"):
        go.positions_from_topocentric(site, [EPOCH], [-5.0], [10.0], height_m=[500e3])
    with pytest.raises(InputError, match="same length"):
        go.positions_from_topocentric(site, [EPOCH, EPOCH], [30.0], [10.0], range_m=[1e6])


def _pomenis_rows(n):
    d = shared_data_dir()
    if d is None:
        pytest.skip("../shared/data not available (Pomenis Starlink observations)")
    path = d / "starlink_pomenis" / "pomenis_observations.csv"
    if not path.is_file():
        pytest.skip(f"{path} missing")
    rows = []
    with open(path) as fh:
        for line in fh:
            if line.startswith("#") or not line.strip() or line.startswith("observation_time"):
                continue
            rows.append(next(csv.reader([line])))
            if len(rows) == n:
                break
    return rows


@pytest.mark.shared_data
def test_pomenis_observations_reconstruct():
    """Real Mount Lemmon data (Fankhauser et al. 2023): time, height (km), alt, az (deg).
    The reconstructed Starlink positions must have the stated height (skyfield's WGS84
    inversion as oracle) and be seen at the stated alt/az from the site (skyfield altaz)."""
    from skyfield.api import wgs84
    from skyfield.positionlib import Geocentric

    from lightcurve.geometry.time import timescale, parse_epoch

    rows = _pomenis_rows(60)
    times = [r[0] for r in rows]
    h = np.array([float(r[1]) for r in rows]) * 1e3
    alt = np.array([float(r[2]) for r in rows])
    az = np.array([float(r[3]) for r in rows])
    site = get_site("mount_lemmon")
    r = go.positions_from_topocentric(site, times, alt, az, height_m=h)
    t = timescale().from_datetimes([parse_epoch(x) for x in times])
    g = Geocentric(r.T / 149597870700.0, t=t)
    np.testing.assert_allclose(wgs84.height_of(g).m, h, atol=0.05)
    topos = wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.height_m)
    rel = (r - topos.at(t).position.m.T)
    # skyfield's altazimuth frame of the site as the oracle (az = atan2(y, x), as skyfield)
    rot = np.moveaxis(topos.rotation_at(t), -1, 0)
    loc = np.einsum("nij,nj->ni", rot, rel)
    a2 = np.degrees(np.arcsin(loc[:, 2] / np.linalg.norm(loc, axis=1)))
    z2 = np.degrees(np.arctan2(loc[:, 1], loc[:, 0])) % 360
    np.testing.assert_allclose(a2, alt, atol=1e-6)
    dz = (z2 - az + 180) % 360 - 180
    assert np.max(np.abs(dz)) < 1e-6
    # Starlink shells at 540-570 km: slant ranges between the height and ~ 2000 km
    slant = np.linalg.norm(rel, axis=1)
    assert np.all((slant > h * 0.99) & (slant < 2.5e6))
