"""Fuzz: CSV recordings (lightcurve.io.recording.read_recording) and their measurement rules.

Property: any bytes, damaged rows, hostile values or column mappings give an
InputError naming the file (and the line/column for row errors) or a valid Lightcurve whose
magnitudes are finite; NaN magnitudes, out-of-order rows, duplicated rows and rows below the
horizon are skipped or sorted with counts in ``attrs``; unknown sites and times outside the
DE421 ephemeris are rejected.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardening_util import (HOSTILE_TEXT, damaged_bytes, fuzz_settings, new_tmp_dir,
                            only_input_error)
from lightcurve import InputError
from lightcurve.io.recording import read_recording, recording_spec_from_section

HEADER = "utc,mag,mag_sigma,site,alt_deg,az_deg,range_m"
# dusk at Mount Lemmon, 2022-03-03 02:00-02:10 UTC: a LEO object at these alt/az is sunlit
GOOD_ROWS = [f"2022-03-03T02:0{k}:00Z,{6 + 0.1 * k:.1f},0.05,mount_lemmon,{30 + 5 * k},{40 * k},8e5"
             for k in range(5)]
GOOD = (HEADER + "\n" + "\n".join(GOOD_ROWS) + "\n").encode()


def _write(data: bytes, name="rec.csv") -> Path:
    p = new_tmp_dir() / name
    p.write_bytes(data)
    return p


def _read(p, spec=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_recording(p, spec)


def _check(out):
    if not isinstance(out, InputError):
        assert np.all(np.isfinite(out.mag)) and np.all(out.mag_sigma > 0)
        assert np.all(np.diff(out.t) >= 0)


@fuzz_settings(120)
@given(st.one_of(st.binary(max_size=300), damaged_bytes(GOOD)))
def test_recording_random_and_damaged_bytes(data):
    p = _write(data)
    _check(only_input_error("CSV recording (read_recording)", _read, p, file=p))


FIELD = st.one_of(HOSTILE_TEXT, st.text(max_size=12),
                  st.sampled_from(["nan", "NaN", "inf", "-inf", "1e308", "-0", "99", "-45",
                                   "2053-10-09T00:00:00Z", "1899-07-01T00:00:00Z", "2022-03-03T02:00:00Z",
                                   "socorro", "atlantis", "", '"quoted, comma"']))


@fuzz_settings(150)
@given(st.lists(st.tuples(st.integers(0, 4), st.integers(0, 6), FIELD), min_size=1, max_size=4))
def test_recording_hostile_fields(edits):
    """Replace single fields of the good file by hostile text (NaN/inf, unicode, huge...)."""
    rows = [r.split(",") for r in GOOD_ROWS]
    for r, c, v in edits:
        rows[r][c] = v.replace("\n", " ").replace("\r", " ")
    p = _write((HEADER + "\n" + "\n".join(",".join(r) for r in rows) + "\n").encode())
    out = only_input_error("CSV recording (read_recording)", _read, p, file=p)
    _check(out)
    if isinstance(out, InputError) and "line" in (out.field or ""):
        assert "line" in str(out)


@fuzz_settings(60)
@given(st.dictionaries(st.sampled_from(["time_column", "mag_column", "sigma_column", "default_sigma_mag",
                                        "site_column", "site", "alt_column", "az_column", "range_column",
                                        "height_column", "range_unit", "height_unit", "comment", "delimiter",
                                        "header", "time_format", "epoch_utc", "bogus"]),
                       st.one_of(st.integers(-3, 9), st.text(max_size=4), st.booleans(),
                                 st.floats(allow_nan=True), st.sampled_from(["utc", "mag", "range_m", ","])),
                       max_size=6))
def test_recording_column_mappings(table):
    """Hostile [recording] tables: validated into a spec or refused (field named)."""
    spec = only_input_error("[recording] table", recording_spec_from_section, table)
    if isinstance(spec, InputError):
        assert "recording" in str(spec)
        return
    p = _write(GOOD)
    _check(only_input_error("CSV recording (read_recording)", _read, p, spec, file=p))


def test_huge_line_count_is_linear():
    """20 000 rows (some NaN) are read with one geometry call; NaN rows counted, not used."""
    rows = [HEADER]
    for k in range(20000):
        mag = "nan" if k % 1000 == 0 else "6.5"
        rows.append(f"2022-03-03T02:{k // 6000:02d}:{(k // 100) % 60:02d}.{k % 100:02d}Z,{mag},0.05,"
                    f"mount_lemmon,45,180,8e5")
    p = _write(("\n".join(rows) + "\n").encode())
    lc = _read(p)
    assert len(lc) == 20000 - 20 and lc.attrs["skipped_nan_mag"] == 20


# ----------------------------------------------------------------------------------------
# measurement rules (docs/robustness.md, CSV recording rows)
# ----------------------------------------------------------------------------------------
def test_nan_magnitudes_skipped_and_counted():
    rows = list(GOOD_ROWS)
    rows[1] = rows[1].replace(",6.1,", ",nan,")
    rows[3] = rows[3].replace(",6.3,", ",,")
    lc = _read(_write((HEADER + "\n" + "\n".join(rows) + "\n").encode()))
    assert len(lc) == 3 and lc.attrs["skipped_nan_mag"] == 2


@pytest.mark.parametrize("value", ["inf", "-inf", "1e400"])
def test_infinite_magnitude_rejected_naming_line(value):
    rows = list(GOOD_ROWS)
    rows[2] = rows[2].replace(",6.2,", f",{value},")
    p = _write((HEADER + "\n" + "\n".join(rows) + "\n").encode())
    with pytest.raises(InputError) as exc:
        _read(p)
    assert str(p) in str(exc.value) and "line 4" in str(exc.value) and "'mag'" in str(exc.value)


def test_out_of_order_rows_sorted_and_counted():
    rows = [GOOD_ROWS[k] for k in (0, 3, 1, 2, 4)]
    lc = _read(_write((HEADER + "\n" + "\n".join(rows) + "\n").encode()))
    assert np.all(np.diff(lc.t) > 0) and lc.attrs["sorted_by_time"] == 1
    assert lc.attrs["n_out_of_order"] == 2  # rows 1 and 2 (0-based 2, 3) come after a later time
    np.testing.assert_allclose(lc.mag, [6.0, 6.1, 6.2, 6.3, 6.4])


def test_identical_duplicate_rows_skipped_and_counted():
    rows = GOOD_ROWS[:3] + [GOOD_ROWS[1], GOOD_ROWS[1]] + GOOD_ROWS[3:]
    lc = _read(_write((HEADER + "\n" + "\n".join(rows) + "\n").encode()))
    assert len(lc) == 5 and lc.attrs["skipped_duplicate"] == 2


def test_conflicting_duplicate_rows_rejected_naming_both_lines():
    rows = GOOD_ROWS + [GOOD_ROWS[1].replace(",6.1,", ",7.5,")]
    p = _write((HEADER + "\n" + "\n".join(rows) + "\n").encode())
    with pytest.raises(InputError) as exc:
        _read(p)
    assert str(p) in str(exc.value) and "lines 3 and 7" in str(exc.value)


def test_same_time_two_sites_is_not_a_duplicate():
    rows = GOOD_ROWS + [GOOD_ROWS[1].replace("mount_lemmon", "socorro")]
    lc = _read(_write((HEADER + "\n" + "\n".join(rows) + "\n").encode()))
    assert len(lc) == 6 and lc.attrs["skipped_duplicate"] == 0


def test_rows_below_the_horizon_skipped_and_counted():
    rows = list(GOOD_ROWS)
    rows[2] = rows[2].replace(",40,80,", ",-10,80,")
    lc = _read(_write((HEADER + "\n" + "\n".join(rows) + "\n").encode()))
    assert len(lc) == 4 and lc.attrs["skipped_below_horizon"] == 1
    assert np.all(lc.elevation_rad >= 0)


UNLIT_ROW = "2022-03-03T11:00:00Z,6.0,0.05,mount_lemmon,40,300,8e5"


def test_unlit_rows_kept_on_request_counted_and_warned():
    """2022-03-03 11:00 UTC: an object 800 km away at 40 deg altitude towards az 300 deg from
    Mount Lemmon is in the Earth's full shadow (conical lit fraction 0; the geometry code is
    cross-checked against skyfield in tests/geometry). ``unlit="keep"`` keeps it, counted and
    warned (for diagnosing shadow effects)."""
    p = _write((HEADER + "\n" + UNLIT_ROW + "\n").encode())
    with pytest.warns(UserWarning, match="shadow"):
        lc = read_recording(p, unlit="keep")
    assert lc.attrs["n_unlit"] == 1 and lc.lit_fraction[0] == 0.0
    assert lc.attrs["unlit_policy"] == "keep" and lc.attrs["skipped_unlit"] == 0


def test_unlit_rows_skipped_and_counted_by_default():
    """The same shadowed row among sunlit ones is skipped by default and counted; a file of
    shadowed rows only is an InputError; a bad policy is an InputError."""
    rows = list(GOOD_ROWS) + [UNLIT_ROW]
    p = _write((HEADER + "\n" + "\n".join(rows) + "\n").encode())
    with warnings.catch_warnings():
        warnings.simplefilter("error")     # nothing kept, so no shadow warning
        lc = read_recording(p)
    ref = _read(_write((HEADER + "\n" + "\n".join(GOOD_ROWS) + "\n").encode()))
    assert lc.attrs["skipped_unlit"] == 1 and lc.attrs["n_unlit"] == 0
    assert lc.attrs["unlit_policy"] == "skip"
    assert len(lc) == len(ref) and np.all(lc.lit_fraction > 0.0)
    np.testing.assert_array_equal(lc.mag, ref.mag)
    with pytest.raises(InputError, match="shadow"):
        read_recording(_write((HEADER + "\n" + UNLIT_ROW + "\n").encode()))
    with pytest.raises(InputError, match="unlit"):
        read_recording(p, unlit="drop")


def test_unknown_site_rejected_naming_line_and_known_ids():
    rows = list(GOOD_ROWS)
    rows[4] = rows[4].replace("mount_lemmon", "atlantis")
    p = _write((HEADER + "\n" + "\n".join(rows) + "\n").encode())
    with pytest.raises(InputError) as exc:
        _read(p)
    msg = str(exc.value)
    assert str(p) in msg and "line 6" in msg and "unknown site" in msg and "socorro" in msg


@pytest.mark.parametrize("when", ["1899-07-01T00:00:00Z", "2053-10-09T12:00:00Z", "2100-01-01T00:00:00Z"])
def test_times_outside_the_ephemeris_rejected(when):
    """DE421 spans 1899-07-29 .. 2053-10-09 (JPL IOM 343R-08-003); the package refuses times
    outside its conservative 1899-07-30 .. 2053-10-08."""
    rows = list(GOOD_ROWS)
    rows[0] = when + rows[0][rows[0].index(","):]
    p = _write((HEADER + "\n" + "\n".join(rows) + "\n").encode())
    with pytest.raises(InputError) as exc:
        _read(p)
    assert str(p) in str(exc.value) and "DE421" in str(exc.value)
