"""Recording columns beyond the basic layout: objects, cameras, bands, exposures, JD times,
duplicates across cameras, and the hardening of the CSV reader (regular files, size caps)."""

from __future__ import annotations

import os

import numpy as np
import pytest
import recgen as G

from lightcurve import InputError
from lightcurve.io.recording import read_recording, read_recordings
from lightcurve.photometry.bands import SUN_MAGNITUDES, sun_magnitude

# one geometry that is sunlit and above the horizon at Mount Lemmon (checked by the tests)
HEAD = "utc,mag,mag_sigma,site,alt_deg,az_deg,range_m"
GEOM = "mount_lemmon,40.0,100.0,1.2e6"
WHEN = "2022-03-21T02:10:00"


def _write(tmp_path, lines, name="r.csv"):
    f = tmp_path / name
    f.write_text("\n".join(lines) + "\n")
    return f


def test_objects_cameras_and_simultaneous_rows(tmp_path):
    """Two objects and two cameras at one instant are data; one camera twice is an error."""
    f = _write(tmp_path, ["utc,object,camera,mag,mag_sigma,site,alt_deg,az_deg,range_m",
                          f"{WHEN},A,c1,6.0,0.05,{GEOM}", f"{WHEN},A,c2,6.1,0.05,{GEOM}",
                          f"{WHEN},B,c1,7.0,0.05,{GEOM}", f"{WHEN},B,c1,7.0,0.05,{GEOM}"])
    out = read_recordings(f)
    assert list(out) == [("A", ""), ("B", "")]
    a, b = out[("A", "")], out[("B", "")]
    assert len(a) == 2 and a.camera_names == ["mount_lemmon/c1", "mount_lemmon/c2"]
    assert len(b) == 1 and b.attrs["skipped_duplicate"] == 1      # an exact copy: skipped
    with pytest.raises(InputError, match="2 objects"):
        read_recording(f)
    g = _write(tmp_path, ["utc,object,camera,mag,mag_sigma,site,alt_deg,az_deg,range_m",
                          f"{WHEN},A,c1,6.0,0.05,{GEOM}", f"{WHEN},A,c1,6.3,0.05,{GEOM}"], "g.csv")
    with pytest.raises(InputError, match=r"lines 2 and 3: two different measurements"):
        read_recording(g)
    assert set(read_recordings(f, objects=["B"])) == {("B", "")}


def test_bands_give_the_sun_magnitude(tmp_path):
    """Willmer (2018): M_V = 4.81, M_B = 5.44 (Vega) → −26.76/−26.13 at 1 au (DM 31.572);
    the V value of the package stays Bernard's −26.74 (eq. 5.2)."""
    assert SUN_MAGNITUDES["V"] == -26.74
    assert sun_magnitude("B") == pytest.approx(5.44 - 5 * np.log10(10 * 206264.806), abs=1e-3)
    assert sun_magnitude("V_AB") == pytest.approx(4.80 - 31.572, abs=1e-9)
    f = _write(tmp_path, ["utc,mag,mag_sigma,site,band,alt_deg,az_deg,range_m",
                          f"{WHEN},6.0,0.05,mount_lemmon,V,40,100,1.2e6",
                          f"{WHEN},6.5,0.05,mount_lemmon,B,40,100,1.2e6"])
    out = read_recordings(f)
    assert {k[1]: v.attrs["sun_mag"] for k, v in out.items()} == {"V": -26.74, "B": sun_magnitude("B")}
    g = _write(tmp_path, ["utc,mag,mag_sigma,site,band,alt_deg,az_deg,range_m",
                          f"{WHEN},6.0,0.05,mount_lemmon,Q,40,100,1.2e6"], "g.csv")
    with pytest.raises(InputError, match="unknown photometric band"):
        read_recording(g)
    # a fixed band / Sun magnitude from the mapping; without either, no band attribute
    spec = {"site": "mount_lemmon", "sigma_column": "mag_sigma", "alt_column": "alt_deg",
            "az_column": "az_deg", "range_column": "range_m"}
    h = _write(tmp_path, ["utc,mag,mag_sigma,alt_deg,az_deg,range_m", f"{WHEN},6.0,0.05,40,100,1.2e6"],
               "h.csv")
    assert read_recording(h, dict(spec, sun_mag=-27.056)).attrs["sun_mag"] == -27.056
    assert read_recording(h, dict(spec, band="g")).attrs["band"] == "g"
    assert "band" not in read_recording(h, spec).attrs


def test_exposure_start_end_give_mid_time_and_duration(tmp_path):
    f = _write(tmp_path, ["exposure_start,exposure_end,mag,mag_sigma,site,alt_deg,az_deg,range_m",
                          f"{WHEN},2022-03-21T02:10:03,6.0,0.05,{GEOM}",
                          f"2022-03-21T02:10:10,2022-03-21T02:10:10.5,6.2,0.05,{GEOM}"])
    lc = read_recording(f, {"time_column": None, "exposure_start_column": "exposure_start",
                            "exposure_end_column": "exposure_end", "sigma_column": "mag_sigma",
                            "site_column": "site", "alt_column": "alt_deg", "az_column": "az_deg",
                            "range_column": "range_m", "epoch_utc": "2022-03-21T02:10:00Z"})
    np.testing.assert_allclose(lc.t, [1.5, 10.25])
    np.testing.assert_allclose(lc.exposure_s, [3.0, 0.5])
    # the default layout reads the same columns by their names
    np.testing.assert_allclose(read_recording(f).exposure_s, [3.0, 0.5])
    # a duration with the stamp at the exposure start: t moves to the middle
    g = _write(tmp_path, ["utc,exposure_s,mag,mag_sigma,site,alt_deg,az_deg,range_m",
                          f"{WHEN},2.0,6.0,0.05,{GEOM}"], "g.csv")
    spec = {"exposure_column": "exposure_s", "time_stamp": "start", "sigma_column": "mag_sigma",
            "site_column": "site", "alt_column": "alt_deg", "az_column": "az_deg",
            "range_column": "range_m", "epoch_utc": "2022-03-21T02:10:00Z"}
    lc = read_recording(g, spec)
    assert lc.t[0] == pytest.approx(1.0) and lc.exposure_s[0] == 2.0
    bad = _write(tmp_path, ["exposure_start,exposure_end,mag,mag_sigma,site,alt_deg,az_deg,range_m",
                            f"{WHEN},2022-03-21T02:09:00,6.0,0.05,{GEOM}"], "bad.csv")
    with pytest.raises(InputError, match="line 2, column 'exposure_end': exposure ends before"):
        read_recording(bad)


def test_jd_times_in_the_default_layout(tmp_path):
    """JD 2459659.5 = 2022-03-21T00:00 UTC (USNO); the default layout reads a ``jd`` column."""
    f = _write(tmp_path, ["jd,mag,mag_sigma,site,alt_deg,az_deg,range_m",
                          f"{2459659.5 + (2 + 10 / 60) / 24!r},6.0,0.05,{GEOM}"])
    lc = read_recording(f)
    assert lc.epoch_utc.startswith("2022-03-21T02:10:00") and lc.attrs["time_format"] == "jd_utc"


def test_no_orbit_for_a_range_only_recording(tmp_path):
    f = _write(tmp_path, ["utc,mag,mag_sigma,site,range_m,phase_deg",
                          f"{WHEN},6.0,0.05,mount_lemmon,1.2e6,60.0"])
    with pytest.raises(InputError, match="needs the object's orbit"):
        read_recording(f)
    g = _write(tmp_path, ["utc,mag,mag_sigma,site,range_m,phase_deg",
                          f"{WHEN},6.0,0.05,mount_lemmon,1.2e6,190.0"], "g.csv")
    with pytest.raises(InputError, match="column 'phase_deg': phase angle out of range"):
        read_recording(g)


def test_special_files_and_size_caps(tmp_path, monkeypatch):
    """A FIFO or /dev/zero is refused at once (regular files only); an oversized CSV before
    reading it; a field beyond the csv module's limit names its line."""
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    msg = G.refused_without_blocking(read_recording, fifo)
    assert msg.startswith("InputError") and "not a regular" in msg
    with pytest.raises(InputError, match="not a regular"):
        read_recording("/dev/zero")
    import lightcurve.io.recording as rec

    f = _write(tmp_path, [HEAD, f"{WHEN},6.0,0.05,{GEOM}"])
    monkeypatch.setattr(rec, "CSV_MAX_BYTES", 10)
    with pytest.raises(InputError, match="too large"):
        read_recording(f)
    monkeypatch.undo()
    g = _write(tmp_path, [HEAD, f'{WHEN},6.0,0.05,"{"x" * 140_000}",40,100,1e6'], "long.csv")
    with pytest.raises(InputError, match="line 2"):
        read_recording(g)


def test_a_csv_given_as_lightcurve_says_import_it(tmp_path):
    from lightcurve.io.lightcurve_h5 import read_lightcurve

    f = _write(tmp_path, [HEAD, f"{WHEN},6.0,0.05,{GEOM}"])
    with pytest.raises(InputError, match="lightcurve import"):
        read_lightcurve(f)


def test_scenario_band_sets_the_sun_magnitude():
    from lightcurve._paths import data_dir
    from lightcurve.studies.scenario import parse_scenario

    text = (data_dir("pipelines") / "default.toml").read_text()
    sc = parse_scenario(text.replace("[measurement]", '[measurement]\nband = "g"'), file="<t>")
    assert sc.measurement.sun_mag == sun_magnitude("g") and sc.measurement.band == "g"
    with pytest.raises(InputError, match="not both"):
        parse_scenario(text.replace("[measurement]", '[measurement]\nband = "g"\nsun_mag = -26.0'),
                       file="<t>")
