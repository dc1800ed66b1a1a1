"""Fuzz: our HDF5 files — lightcurves (read_lightcurve) and CSS recordings (css.recording).

Property: random bytes, truncated or bit-flipped files, datasets of the wrong type,
shape or value, and hostile attributes give an InputError naming the file, or a valid object.
HDF5 reading never unpickles (h5py has no pickle path; object dtypes are refused).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardening_util import (damaged_bytes, fuzz_settings, new_tmp_dir, only_input_error,
                            small_curve)
from lightcurve import InputError
from lightcurve.io.lightcurve_h5 import read_lightcurve


def _tmp(name="lc.h5") -> Path:
    return new_tmp_dir() / name


GOOD_PATH = _tmp()
small_curve().write(GOOD_PATH)
GOOD = GOOD_PATH.read_bytes()

DATASETS = ["t", "mag", "mag_sigma", "site", "sites/name", "sites/lla_deg_m", "geometry/r_obj_eci_m",
            "geometry/r_site_eci_m", "geometry/r_sun_eci_m", "geometry/lit_fraction",
            "geometry/elevation_rad", "truth/q", "truth/omega_rad_s", "truth/mag"]
HOSTILE_ARRAYS = st.one_of(
    st.sampled_from([np.array([]), np.array(np.nan), np.full(8, np.nan), np.full(8, np.inf),
                     np.full((8, 3), -np.inf), np.arange(8)[::-1].astype(float), np.zeros((8, 4)),
                     np.full(8, -1), np.full(8, 99), np.array([b"x", b"y"]), np.zeros((2, 2, 2)),
                     np.full(8, 1e308), np.array(["a", "b"], dtype=h5py.string_dtype()),
                     np.zeros(8, dtype=np.complex128), np.zeros(8, dtype=bool),
                     np.zeros(8, dtype=[("a", "f8"), ("b", "i4")])]),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=10).map(np.array))
HOSTILE_ATTRS = st.one_of(st.integers(-5, 5), st.text(max_size=30), st.floats(allow_nan=True),
                          st.sampled_from(["2020-02-30T00:00:00Z", "2100-01-01T00:00:00Z", "", "nan",
                                           "1899-07-29T00:00:00Z"]),
                          st.just(np.array([1, 2, 3])))


@fuzz_settings(100)
@given(st.one_of(st.binary(max_size=2000), damaged_bytes(GOOD),
                 st.integers(0, len(GOOD)).map(lambda k: GOOD[:k])))
def test_lightcurve_h5_random_truncated_flipped(data):
    p = _tmp()
    p.write_bytes(data)
    out = only_input_error("lightcurve HDF5 (read_lightcurve)", read_lightcurve, p, file=p)
    if not isinstance(out, InputError):
        out.validate()


@fuzz_settings(120)
@given(st.sampled_from(DATASETS), st.one_of(HOSTILE_ARRAYS, st.none()))
def test_lightcurve_h5_hostile_datasets(name, value):
    p = _tmp()
    p.write_bytes(GOOD)
    with h5py.File(p, "r+") as h:
        del h[name]
        if value is not None:
            h[name] = value
    out = only_input_error("lightcurve HDF5 (read_lightcurve)", read_lightcurve, p, file=p)
    if not isinstance(out, InputError):
        assert np.all(np.isfinite(out.t)) and not np.any(np.isinf(out.mag))


@fuzz_settings(60)
@given(st.sampled_from(["format_version", "epoch_utc", "scenario", "meta_shape", "meta_x"]),
       st.one_of(HOSTILE_ATTRS, st.none()))
def test_lightcurve_h5_hostile_attributes(name, value):
    p = _tmp()
    p.write_bytes(GOOD)
    with h5py.File(p, "r+") as h:
        if name in h.attrs:
            del h.attrs[name]
        if value is not None:
            h.attrs[name] = value
    only_input_error("lightcurve HDF5 (read_lightcurve)", read_lightcurve, p, file=p)


def test_group_where_dataset_expected_and_external_link():
    p = _tmp()
    p.write_bytes(GOOD)
    with h5py.File(p, "r+") as h:
        del h["mag"]
        h.create_group("mag")
        del h["t"]
        h["t"] = h5py.ExternalLink("/etc/passwd", "/x")  # a link out of the file
    with pytest.raises(InputError, match=str(p)):
        read_lightcurve(p)


def test_huge_declared_dataset_refused_without_reading():
    """A chunked 'mag' dataset declaring 4e8 elements (never written: no disk used) is refused
    from its declared size."""
    p = _tmp()
    p.write_bytes(GOOD)
    with h5py.File(p, "r+") as h:
        del h["mag"]
        h.create_dataset("mag", shape=(400_000_000,), dtype="f8", chunks=(1024,))
    with pytest.raises(InputError) as exc:
        read_lightcurve(p)
    assert str(p) in str(exc.value) and "mag" in str(exc.value)


@pytest.mark.parametrize("mutate, frag", [
    (lambda h: h["mag"].__setitem__(3, np.inf), "infinite magnitude"),
    (lambda h: h["mag_sigma"].__setitem__(2, np.nan), "mag_sigma"),
    (lambda h: h["t"].__setitem__(slice(2, 4), [100.0, 5.0]), "non-decreasing"),
    (lambda h: (h["t"].__setitem__(2, h["t"][1]), h["site"].__setitem__(2, h["site"][1])), "duplicated"),
    (lambda h: h["site"].__setitem__(1, 7), "site index out of range"),
    (lambda h: h.attrs.__setitem__("epoch_utc", "2053-10-07T23:59:50Z"), "DE421"),
    (lambda h: h.attrs.__setitem__("epoch_utc", "yesterday"), "epoch_utc"),
])
def test_measurement_rules_in_hdf5(mutate, frag):
    """inf magnitudes, bad sigmas, non-monotonic or duplicated (time, site) rows, unknown site
    indices and times outside DE421 are rejected naming the file and the dataset."""
    p = _tmp()
    p.write_bytes(GOOD)
    with h5py.File(p, "r+") as h:
        mutate(h)
    with pytest.raises(InputError) as exc:
        read_lightcurve(p)
    assert str(p) in str(exc.value) and frag in str(exc.value)


def test_nan_magnitudes_are_kept_as_not_measured_and_counted():
    p = _tmp()
    p.write_bytes(GOOD)
    with h5py.File(p, "r+") as h:
        h["mag"][2] = np.nan
        h["mag"][5] = np.nan
    lc = read_lightcurve(p)
    assert lc.count_unusable() == {"nan_mag": 2}


def test_same_time_at_two_sites_is_allowed():
    p = _tmp()
    p.write_bytes(GOOD)
    with h5py.File(p, "r+") as h:
        t = h["t"][()]
        t[1] = t[0]  # site 0 and site 1 at the same instant
        h["t"][...] = t
    assert len(read_lightcurve(p)) == 8


# ----------------------------------------------------------------------------------------
# CSS recordings (lightcurve.css.recording)
# ----------------------------------------------------------------------------------------
def _css_good() -> bytes:
    p = _tmp("css.h5")
    with h5py.File(p, "w") as f:
        f.attrs["format"] = "lightcurve-css"
        f.attrs["epoch_utc"] = "2015-03-01T00:00:00Z"
        f["t"] = np.arange(6) * 0.5
        f["y"] = np.abs(np.random.default_rng(1).normal(size=(6, 4)))
        f["normals"] = np.eye(4, 3)
        f["fov_half_angle_rad"] = np.full(4, 1.2)
        f["gyro_rad_s"] = np.zeros((6, 3))
        g = f.create_group("truth")
        g["s_body"] = np.tile([1.0, 0, 0], (6, 1))
    return p.read_bytes()


CSS_GOOD = _css_good()


@fuzz_settings(60)
@given(st.one_of(st.binary(max_size=1000), damaged_bytes(CSS_GOOD)))
def test_css_recording_damaged(data):
    from lightcurve.css.recording import read_css_recording

    p = _tmp("css.h5")
    p.write_bytes(data)
    only_input_error("CSS HDF5 recording (read_css_recording)", read_css_recording, p, file=p)


@fuzz_settings(80)
@given(st.sampled_from(["t", "y", "normals", "fov_half_angle_rad", "gyro_rad_s", "truth"]),
       st.one_of(HOSTILE_ARRAYS, st.none()))
def test_css_recording_hostile_datasets(name, value):
    from lightcurve.css.recording import read_css_recording

    p = _tmp("css.h5")
    p.write_bytes(CSS_GOOD)
    with h5py.File(p, "r+") as f:
        del f[name]
        if value is not None:
            f[name] = value
    out = only_input_error("CSS HDF5 recording (read_css_recording)", read_css_recording, p, file=p)
    if not isinstance(out, InputError):
        assert np.all(np.isfinite(out["t"])) and np.all(np.isfinite(out["y"]))
        assert np.all(np.isfinite(out["normals"]))
