"""CSV recording import (lightcurve.io.recording; docs/formats.md "Recordings (CSV)").

Oracles: the CSV's own topocentric columns (our GCRS object positions must reproduce the
recorded altitude/azimuth through the independent ENU path of compute_geometry, the recorded
height through geodetic_height_m, and the recorded slant range as |r_obj − r_site|), and the
scenario's orbit for files without topocentric columns.
"""

from __future__ import annotations

import numpy as np
import pytest

from lightcurve import InputError
from lightcurve._paths import data_dir, shared_data_dir
from lightcurve.geometry.frames import itrs_rotation
from lightcurve.geometry.orbits import geodetic_height_m, positions_from_topocentric
from lightcurve.geometry.time import skyfield_times
from lightcurve.io.lightcurve_h5 import read_lightcurve
from lightcurve.io.recording import RecordingSpec, read_recording, recording_spec_from_section
from lightcurve.studies.scenario import load_scenario

SHARED = shared_data_dir()
POMENIS = None if SHARED is None else SHARED / "starlink_pomenis" / "pomenis_observations.csv"
needs_data = pytest.mark.skipif(POMENIS is None or not POMENIS.exists(),
                                reason="../shared/data/starlink_pomenis is not available")

POMENIS_MAP = {"time_column": "observation_time", "mag_column": "ab_magnitude",
               "default_sigma_mag": 0.1, "site": "mount_lemmon", "alt_column": "satellite_altitude",
               "az_column": "satellite_azimuth", "height_column": "satellite_height",
               "height_unit": "km", "epoch_utc": "2022-01-25T00:00:00Z"}


def _raw_csv(path):
    """Independent plain reading of the Pomenis file (comment '#', header, 5 columns)."""
    rows = [ln.split(",") for ln in path.read_text().splitlines()
            if ln.strip() and not ln.lstrip().startswith("#")]
    return rows[0], rows[1:]


@needs_data
def test_pomenis_import_reproduces_the_recorded_geometry():
    lc = read_recording(POMENIS, POMENIS_MAP)
    header, rows = _raw_csv(POMENIS)
    # SOURCE.md: 1,173 observations, no NaN magnitudes, no skips
    assert len(rows) == 1173 and len(lc) == 1173
    assert lc.attrs["skipped_nan_mag"] == 0 and lc.attrs["n_rows"] == 1173
    assert not lc.has_truth and lc.site_names == ["mount_lemmon"]
    # the file is not in time order: sorted, and said so
    assert lc.attrs["sorted_by_time"] == 1 and lc.attrs["n_out_of_order"] > 0
    assert np.all(np.diff(lc.t) >= 0)
    # match rows by (time, magnitude) — every recorded value must be reproduced
    from datetime import datetime, timezone

    ep = datetime(2022, 1, 25, tzinfo=timezone.utc)
    t_csv = np.array([(datetime.fromisoformat(r[0]).replace(tzinfo=timezone.utc) - ep).total_seconds()
                      for r in rows])
    h_csv, alt_csv, az_csv, mag_csv = (np.array([float(r[k]) for r in rows]) for k in (1, 2, 3, 4))
    order = np.lexsort((mag_csv, t_csv))
    order_lc = np.lexsort((lc.mag, lc.t))
    np.testing.assert_array_equal(lc.t[order_lc], t_csv[order])
    np.testing.assert_array_equal(lc.mag[order_lc], mag_csv[order])
    assert np.all(lc.mag_sigma == 0.1)
    # elevation through compute_geometry's ENU path equals the recorded altitude (geometric)
    np.testing.assert_allclose(np.degrees(lc.elevation_rad[order_lc]), alt_csv[order], atol=1e-6)
    # the recorded height (km) above WGS84
    R = itrs_rotation(skyfield_times(lc.epoch_utc, lc.t), exact=True)
    h = geodetic_height_m(np.einsum("nij,nj->ni", R, lc.r_obj_eci_m))
    np.testing.assert_allclose(h[order_lc], 1000 * h_csv[order], atol=0.05)
    assert np.all(lc.lit_fraction > 0)  # every observed satellite was (at least partly) sunlit


@needs_data
def test_pomenis_import_through_the_shipped_pipeline(tmp_path):
    sc = load_scenario(data_dir("pipelines") / "real" / "starlink_pomenis.toml")
    lc = read_recording(POMENIS, sc)
    assert len(lc) == 1173 and lc.epoch_utc == "2022-01-25T00:00:00Z"
    p = lc.write(tmp_path / "pomenis.h5")
    back = read_lightcurve(p)
    np.testing.assert_array_equal(back.t, lc.t)
    np.testing.assert_array_equal(back.r_obj_eci_m, lc.r_obj_eci_m)
    assert back.attrs["geometry_source"] == "topocentric" and not back.has_truth


def _truth_rows():
    """Three epochs at Mount Lemmon with known alt/az/height (m) → GCRS positions (oracle)."""
    utc = ["2022-03-03T03:10:00", "2022-03-03T03:00:00", "2022-03-03T03:05:30.5"]
    alt = np.array([40.0, 25.5, 70.25])
    az = np.array([300.0, 45.0, 180.0])
    h_m = np.array([550e3, 480e3, 520e3])
    r = positions_from_topocentric("mount_lemmon", utc, alt, az, height_m=h_m)
    return utc, alt, az, h_m, r


def test_mapping_for_another_layout(tmp_path):
    """Other column order, ';' delimiter, '%' comments, km heights, sigma column, a NaN row."""
    utc, alt, az, h_m, r = _truth_rows()
    lines = ["% exported by some pipeline", "% units: km, deg", "",
             "h_km;mag_v;when;err;A;Z   % trailing comment"]
    for k in range(3):
        lines.append(f"{h_m[k] / 1000:.6f};{5.0 + k};{utc[k]};0.0{k + 2};{az[k]};{alt[k]}")
    lines.insert(5, "500.0;nan;2022-03-03T03:01:00;0.05;10.0;30.0")  # skipped and counted
    f = tmp_path / "other.csv"
    f.write_text("\n".join(lines) + "\n")
    spec = recording_spec_from_section({
        "time_column": "when", "mag_column": 1, "sigma_column": "err", "site": "mount_lemmon",
        "alt_column": "Z", "az_column": "A", "height_column": 0, "height_unit": "km",
        "comment": "%", "delimiter": ";"})
    # two of these made-up rows fall in the Earth's shadow (skipped by default);
    # this test is about the layout, so they are kept
    with pytest.warns(UserWarning, match="shadow"):
        lc = read_recording(f, spec, unlit="keep")
    assert len(lc) == 3 and lc.attrs["skipped_nan_mag"] == 1 and lc.attrs["n_unlit"] == 2
    # sorted by time: 03:00 (row 1), 03:05:30.5 (row 2), 03:10 (row 0)
    order = [1, 2, 0]
    assert lc.epoch_utc.startswith("2022-03-03T03:00:00")
    np.testing.assert_allclose(lc.t, [0.0, 330.5, 600.0])
    np.testing.assert_allclose(lc.mag, [6.0, 7.0, 5.0])
    np.testing.assert_allclose(lc.mag_sigma, [0.03, 0.04, 0.02])
    assert lc.attrs["sorted_by_time"] == 1
    np.testing.assert_allclose(lc.r_obj_eci_m, r[order], atol=1e-3)


def test_default_layout_two_sites_and_range(tmp_path):
    """Default columns utc, mag, mag_sigma, site, alt_deg, az_deg, range_m: |r_obj − r_site| = range."""
    rng = np.random.default_rng(3)
    rows = ["utc,mag,mag_sigma,site,alt_deg,az_deg,range_m"]
    want = []
    for k in range(6):
        site = ["mount_lemmon", "socorro"][k % 2]
        a, z, d = rng.uniform(15, 85), rng.uniform(0, 360), rng.uniform(6e5, 2e6)
        rows.append(f"2022-05-01T04:{10 + k:02d}:00Z,{6 + 0.1 * k},0.05,{site},{a},{z},{d}")
        want.append((site, d))
    f = tmp_path / "default.csv"
    f.write_text("\n".join(rows))
    # random made-up rows: two fall in the Earth's shadow (skipped by default); this
    # test is about the layout and the ranges, so they are kept
    with pytest.warns(UserWarning, match="shadow"):
        lc = read_recording(f, unlit="keep")
    assert lc.site_names == ["mount_lemmon", "socorro"]
    np.testing.assert_array_equal(lc.site, [0, 1, 0, 1, 0, 1])
    np.testing.assert_allclose(lc.range_obs_m, [d for _, d in want], rtol=0, atol=1e-3)
    assert lc.attrs["sorted_by_time"] == 0 and lc.attrs["n_out_of_order"] == 0


def test_geometry_from_the_scenario_orbit(tmp_path):
    """No topocentric columns: positions from the scenario's [orbit] at the scenario epoch."""
    sc = load_scenario(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")
    f = tmp_path / "orbit.csv"
    f.write_text("utc,mag,mag_sigma,site\n"
                 "2020-03-01T08:08:50Z,7.1,0.1,socorro\n2020-03-01T08:08:45Z,7.0,0.1,socorro\n")
    lc = read_recording(f, sc)
    assert lc.epoch_utc == sc.epoch_utc and lc.attrs["geometry_source"] == "orbit"
    np.testing.assert_allclose(lc.t, [5.0, 10.0])
    r, _ = sc.orbit.positions(sc.epoch_utc, lc.t)
    np.testing.assert_allclose(lc.r_obj_eci_m, r, atol=1e-6)


BAD = [
    # (data line, expected fragments of the message)
    ("2022-05-01T04:10:00Z,abc,0.05,mount_lemmon,40,100,8e5", ["line 3", "'mag'", "not a number"]),
    ("2022-13-01T04:10:00Z,6.0,0.05,mount_lemmon,40,100,8e5", ["line 3", "'utc'", "iso"]),
    ("2022-05-01T04:10:00Z,6.0,-0.05,mount_lemmon,40,100,8e5", ["line 3", "'mag_sigma'", "positive"]),
    ("2022-05-01T04:10:00Z,6.0,0.05,mount_lemmon,95,100,8e5", ["line 3", "'alt_deg'", "out of range"]),
    ("2022-05-01T04:10:00Z,6.0,0.05,mount_lemmon,40,100,-8e5", ["line 3", "'range_m'", "negative"]),
    ("2022-05-01T04:10:00Z,6.0,0.05,atlantis,40,100,8e5", ["line 3", "'site'", "unknown site"]),
    ("2022-05-01T04:10:00Z,6.0,0.05,mount_lemmon,40,100", ["line 3", "expected 7 fields"]),
]


@pytest.mark.parametrize("line,frags", BAD)
def test_bad_rows_name_file_line_and_column(tmp_path, line, frags):
    f = tmp_path / "bad.csv"
    f.write_text("utc,mag,mag_sigma,site,alt_deg,az_deg,range_m\n"
                 "2022-05-01T04:09:00Z,6.0,0.05,mount_lemmon,40,100,8e5\n" + line + "\n")
    with pytest.raises(InputError) as ei:
        read_recording(f)
    msg = str(ei.value)
    assert "bad.csv" in msg
    for frag in frags:
        assert frag in msg, (frag, msg)


def test_bad_files_and_mappings(tmp_path):
    f = tmp_path / "h.csv"
    # a height below the site (2791 m at Mount Lemmon) has no line of sight
    f.write_text("t,m,alt,az,h\n2022-05-01T04:10:00,6,40,100,1.0\n")
    spec = {"time_column": "t", "mag_column": "m", "default_sigma_mag": 0.1, "site": "mount_lemmon",
            "alt_column": "alt", "az_column": "az", "height_column": "h", "height_unit": "km"}
    with pytest.raises(InputError, match=r"line 2, column 'h'.*not above the site"):
        read_recording(f, spec)
    with pytest.raises(InputError, match="'nope' not found"):
        read_recording(f, dict(spec, mag_column="nope"))
    with pytest.raises(InputError, match="default_sigma_mag"):
        read_recording(f, {k: v for k, v in spec.items() if k != "default_sigma_mag"})
    with pytest.raises(InputError, match="not both"):
        recording_spec_from_section(dict(spec, range_column="r"))
    with pytest.raises(InputError, match="unknown key"):
        recording_spec_from_section(dict(spec, heigth_unit="km"))
    with pytest.raises(InputError, match="allowed: m, km"):
        recording_spec_from_section(dict(spec, height_unit="mi"))
    with pytest.raises(InputError, match="0-based indices"):
        recording_spec_from_section(dict(spec, header=False))
    with pytest.raises(InputError, match="file not found"):
        read_recording(tmp_path / "missing.csv", spec)
    g = tmp_path / "nan.csv"
    g.write_text("utc,mag,mag_sigma,site\n2022-05-01T04:10:00,nan,0.1,socorro\n")
    with pytest.raises(InputError, match="no measurement rows"):
        read_recording(g)
    assert RecordingSpec().time_column == "utc"


def test_unix_and_mjd_time_formats(tmp_path):
    """unix_s and mjd_utc give the same epochs as ISO text (2022-05-01T04:00Z = Unix 1651377600
    = MJD 59700 + 4/24; MJD 59700 is 2022-05-01, USNO calendar)."""
    vals = {"iso": "2022-05-01T04:00:00", "unix_s": "1651377600", "mjd_utc": repr(59700 + 4 / 24),
            "jd_utc": repr(2459700.5 + 4 / 24)}
    for fmt, val in vals.items():
        f = tmp_path / f"{fmt}.csv"
        f.write_text(f"time,mag,alt,az,rng\n{val},6.0,40,100,800\n")
        # the made-up row is in the Earth's shadow: kept here (this test is about times)
        with pytest.warns(UserWarning, match="shadow"):
            lc = read_recording(f, {"time_column": "time", "mag_column": "mag",
                                    "default_sigma_mag": 0.1, "site": "socorro",
                                    "time_format": fmt, "alt_column": "alt", "az_column": "az",
                                    "range_column": "rng", "range_unit": "km",
                                    "epoch_utc": "2022-05-01T00:00:00Z"}, unlit="keep")
        assert lc.t[0] == pytest.approx(14400.0, abs=1e-4), fmt
        assert lc.range_obs_m[0] == pytest.approx(8e5, abs=1e-3)
