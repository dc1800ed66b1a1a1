"""Lightcurve HDF5 round trip, validation and atomic writes (DESIGN.md 'Files')."""

import h5py
import numpy as np
import pytest

from lightcurve import InputError
from lightcurve.io.lightcurve_h5 import Lightcurve, read_lightcurve


def make_lc(n=20, truth=True):
    rng = np.random.default_rng(1)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    r_obj = rng.normal(size=(n, 3))
    r_obj *= 7e6 / np.linalg.norm(r_obj, axis=1, keepdims=True)   # outside the Earth (|r| = 7000 km)
    return Lightcurve(
        epoch_utc="2020-03-01T08:08:40Z", t=np.arange(n) * 5.0, mag=10 + rng.normal(size=n),
        mag_sigma=np.full(n, 0.03), site=np.zeros(n, int), site_names=["socorro"],
        site_lla_deg_m=[[33.8173, -106.66, 1500.0]], r_obj_eci_m=r_obj,
        r_site_eci_m=rng.normal(size=(n, 3)) * 6.4e6, r_sun_eci_m=rng.normal(size=(n, 3)) * 1.5e11,
        lit_fraction=np.ones(n), elevation_rad=np.full(n, 0.5),
        truth_q=q if truth else None, truth_omega_rad_s=rng.normal(size=(n, 3)) if truth else None,
        truth_mag=np.full(n, 10.0) if truth else None, scenario_toml="[scenario]\n", attrs={"r_percent": 1.0})


def test_round_trip(tmp_path):
    lc = make_lc()
    p = lc.write(tmp_path / "a.h5")
    back = read_lightcurve(p)
    for name in ("t", "mag", "mag_sigma", "site", "r_obj_eci_m", "truth_q", "truth_mag", "lit_fraction"):
        np.testing.assert_array_equal(getattr(back, name), getattr(lc, name))
    assert back.site_names == ["socorro"] and back.epoch_utc == lc.epoch_utc
    assert back.attrs["r_percent"] == 1.0
    # documented layout (docs/formats.md)
    with h5py.File(p) as h:
        for ds in ("t", "mag", "mag_sigma", "site", "sites/name", "sites/lla_deg_m", "geometry/r_obj_eci_m",
                   "geometry/r_site_eci_m", "geometry/r_sun_eci_m", "truth/q", "truth/omega_rad_s", "truth/mag"):
            assert ds in h, ds
        assert h.attrs["format_version"] == 1


def test_geometry_properties():
    lc = make_lc()
    s, o = lc.obj_to_sun_unit, lc.obj_to_obs_unit
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 1.0)
    ph = lc.phase_angle_rad
    np.testing.assert_allclose(np.cos(ph), np.sum(s * o, axis=1))


def test_truncated_file_is_clear_error(tmp_path):
    p = make_lc().write(tmp_path / "a.h5")
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError, match="a.h5"):
        read_lightcurve(p)


def test_missing_dataset_named(tmp_path):
    p = make_lc().write(tmp_path / "a.h5")
    with h5py.File(p, "a") as h:
        del h["mag_sigma"]
    with pytest.raises(InputError, match="mag_sigma"):
        read_lightcurve(p)


def test_nonmonotonic_times_rejected(tmp_path):
    p = make_lc().write(tmp_path / "a.h5")
    with h5py.File(p, "a") as h:
        t = h["t"][()]
        t[5] = -1.0
        h["t"][...] = t
    with pytest.raises(InputError, match="non-decreasing"):
        read_lightcurve(p)


def test_failed_write_keeps_previous_file(tmp_path):
    lc = make_lc()
    p = lc.write(tmp_path / "a.h5")
    before = p.read_bytes()
    lc.attrs["bad"] = object()  # h5py cannot store it: the write fails midway
    with pytest.raises(TypeError):
        lc.write(p)
    assert p.read_bytes() == before
    assert [f.name for f in tmp_path.iterdir()] == ["a.h5"]  # no temporary left behind
