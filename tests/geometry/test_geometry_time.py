"""Time and ephemeris: skyfield is the oracle (Sun positions to 1e-6 relative)."""

import warnings
from datetime import datetime, timezone

import numpy as np
import pytest

from lightcurve.errors import InputError
from lightcurve.geometry import time as gtime

EPOCH = "2020-03-01T08:08:40Z"  # Bernard (2021) LEO test case epoch


def _oracle_times(n=7, step=600.0):
    # independent construction of the same instants through skyfield's own UTC API
    ts = gtime.timescale()
    return ts.utc(2020, 3, 1, 8, 8, 40.0 + step * np.arange(n))


def test_sun_matches_skyfield_astrometric_and_geometric():
    eph = gtime.ephemeris()
    t_s = 600.0 * np.arange(7)
    t = _oracle_times()
    mine = gtime.sun_position_gcrs(EPOCH, t_s)
    ref = eph["earth"].at(t).observe(eph["sun"]).position.m.T
    assert mine.shape == (7, 3)
    assert np.max(np.linalg.norm(mine - ref, axis=1) / np.linalg.norm(ref, axis=1)) < 1e-6
    geo = gtime.sun_position_gcrs(EPOCH, t_s, light_time=False)
    ref_geo = (eph["sun"] - eph["earth"]).at(t).position.m.T
    assert np.max(np.linalg.norm(geo - ref_geo, axis=1) / np.linalg.norm(ref_geo, axis=1)) < 1e-6
    # light time 499 s × the Sun's barycentric speed (~10 m/s) ≈ 5 km: relative ~5e-8, so the
    # switch does something, and the default is the light-time-corrected one
    d = np.linalg.norm(geo - mine, axis=1) / np.linalg.norm(ref, axis=1)
    assert np.all((d > 1e-8) & (d < 2e-7))
    # Earth–Sun distance on 1 March ≈ 0.9908 au (Astronomical Almanac 2020)
    assert abs(np.linalg.norm(mine[0]) / gtime.AU_M - 0.9908) < 0.001


def test_moon_matches_skyfield():
    eph = gtime.ephemeris()
    mine = gtime.moon_position_gcrs(EPOCH, 600.0 * np.arange(7))
    ref = eph["earth"].at(_oracle_times()).observe(eph["moon"]).position.m.T
    assert np.max(np.linalg.norm(mine - ref, axis=1) / np.linalg.norm(ref, axis=1)) < 1e-6
    assert np.all((np.linalg.norm(mine, axis=1) > 3.5e8) & (np.linalg.norm(mine, axis=1) < 4.1e8))


def test_skyfield_times_offsets_and_scalar():
    t = gtime.skyfield_times(EPOCH, [0.0, 10.0, 3600.5])
    # two-part Julian dates keep microsecond precision (a single float JD would not)
    dt = ((t.whole - t.whole[0]) + (t.tt_fraction - t.tt_fraction[0])) * 86400.0
    np.testing.assert_allclose(dt, [0.0, 10.0, 3600.5], atol=1e-6)
    t1 = gtime.skyfield_times("2020-03-01 08:08:40.25", 0.0)
    assert t1.tt.shape == (1,)
    assert t1.utc_datetime()[0] == datetime(2020, 3, 1, 8, 8, 40, 250000, tzinfo=timezone.utc)


def test_parse_epoch_forms_and_errors():
    ref = datetime(2020, 3, 1, 8, 8, 40, tzinfo=timezone.utc)
    assert gtime.parse_epoch("2020-03-01T08:08:40Z") == ref
    assert gtime.parse_epoch("2020-03-01T08:08:40") == ref
    assert gtime.parse_epoch("2020-03-01T01:08:40-07:00") == ref
    assert gtime.parse_epoch(datetime(2020, 3, 1, 8, 8, 40)) == ref
    with pytest.raises(InputError, match="ISO 8601"):
        gtime.parse_epoch("1 March 2020")
    with pytest.raises(InputError, match="DE421"):
        gtime.parse_epoch("2060-01-01T00:00:00Z")
    with pytest.raises(InputError, match="DE421"):
        gtime.sun_position_gcrs("1899-08-01T00:00:00Z", [-86400.0 * 10])


def test_offline_loader_and_no_expiry_warning():
    import skyfield_data
    import os

    pkg = os.path.join(os.path.dirname(os.path.abspath(skyfield_data.__file__)), "data")
    assert os.path.samefile(gtime.ephemeris_dir(), pkg)
    assert os.path.samefile(gtime.loader().directory, pkg)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gtime.sun_position_gcrs(EPOCH, [0.0])
