"""Element-set files (TLE with/without name lines, OMM JSON/XML/CSV) and ``lightcurve passes``.

Oracles: sgp4's own exporter writes the TLE lines; skyfield (EarthSatellite, altaz,
is_sunlit on DE421) is the independent reference for positions and for pass visibility.
"""

from __future__ import annotations

import json
import os
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest
import recgen as G  # tests/recgen.py: the plain-NumPy recording generator

from lightcurve import InputError
from lightcurve.cli import main
from lightcurve.geometry.tle import (
    ElementAgeWarning,
    check_element_age,
    find_element_set,
    load_element_sets,
)

EPOCH = datetime(2022, 3, 21, 2, 0, tzinfo=timezone.utc)


def _lines(num, a_km=7300.0, e=0.001, i=53.0, raan=40.0, argp=10.0, M=100.0, epoch=EPOCH):
    from sgp4.api import WGS72, Satrec
    from sgp4.exporter import export_tle

    s = Satrec()
    n = np.sqrt(G.MU / (a_km * 1e3) ** 3) * 60.0
    jd = 2440587.5 + epoch.timestamp() / 86400.0
    s.sgp4init(WGS72, "i", num, jd - 2433281.5, 1e-4, 0.0, 0.0, e, np.radians(argp),
               np.radians(i), np.radians(M), n, np.radians(raan))
    s.classification = "U"
    s.intldesg = "22001A"
    return export_tle(s), dict(a_km=a_km, e=e, i=i, raan=raan, argp=argp, M=M, n=n)


def _omm(num, name, el, epoch=EPOCH):
    return {"OBJECT_NAME": name, "OBJECT_ID": "2022-001A", "EPOCH": epoch.strftime("%Y-%m-%dT%H:%M:%S.%f"),
            "MEAN_MOTION": el["n"] * 1440 / (2 * np.pi), "ECCENTRICITY": el["e"],
            "INCLINATION": el["i"], "RA_OF_ASC_NODE": el["raan"], "ARG_OF_PERICENTER": el["argp"],
            "MEAN_ANOMALY": el["M"], "EPHEMERIS_TYPE": 0, "CLASSIFICATION_TYPE": "U",
            "NORAD_CAT_ID": num, "ELEMENT_SET_NO": 999, "REV_AT_EPOCH": 1, "BSTAR": 1e-4,
            "MEAN_MOTION_DOT": 0.0, "MEAN_MOTION_DDOT": 0.0}


def test_formats_give_the_same_positions(tmp_path):
    (l1, l2), el = _lines(90001)
    (m1, m2), el2 = _lines(90002, i=97.0, raan=200.0)
    t = np.array([0.0, 600.0])
    ts, _ = G.skyfield()
    want = G.sgp4_gcrs(ts, l1, l2, G.utc_times(EPOCH, t))
    files = {
        "2le": f"{l1}\n{l2}\n{m1}\n{m2}\n",
        "3le": f"# a comment\nSAT ONE\n{l1}\n{l2}\n\n0 SAT TWO\n{m1}\n{m2}\n",
        "json": json.dumps([_omm(90001, "SAT ONE", el), _omm(90002, "SAT TWO", el2)]),
        "csv": ",".join(_omm(90001, "SAT ONE", el)) + "\n" + "\n".join(
            ",".join(str(v) for v in _omm(n, nm, e).values())
            for n, nm, e in ((90001, "SAT ONE", el), (90002, "SAT TWO", el2))) + "\n",
        "xml": "<ndm><omm><body>" + "".join(
            f"<segment><metadata><OBJECT_NAME>{nm}</OBJECT_NAME><OBJECT_ID>2022-001A</OBJECT_ID>"
            f"</metadata><data><meanElements>"
            + "".join(f"<{k}>{v}</{k}>" for k, v in _omm(n, nm, e).items()
                      if k in ("EPOCH", "MEAN_MOTION", "ECCENTRICITY", "INCLINATION",
                               "RA_OF_ASC_NODE", "ARG_OF_PERICENTER", "MEAN_ANOMALY"))
            + "</meanElements><tleParameters>"
            + "".join(f"<{k}>{v}</{k}>" for k, v in _omm(n, nm, e).items()
                      if k in ("EPHEMERIS_TYPE", "CLASSIFICATION_TYPE", "NORAD_CAT_ID",
                               "ELEMENT_SET_NO", "REV_AT_EPOCH", "BSTAR", "MEAN_MOTION_DOT",
                               "MEAN_MOTION_DDOT"))
            + "</tleParameters></data></segment>"
            for n, nm, e in ((90001, "SAT ONE", el), (90002, "SAT TWO", el2))) + "</body></omm></ndm>",
    }
    for kind, text in files.items():
        f = tmp_path / f"e.{kind}"
        f.write_text(text)
        sets = load_element_sets(f)
        assert [s.norad for s in sets] == [90001, 90002], kind
        es = find_element_set(sets, 90001)
        if kind != "2le":
            assert find_element_set(sets, "sat one").norad == 90001, kind
            assert find_element_set(sets, " SAT  TWO ").norad == 90002, kind
        r, _ = es.positions(EPOCH.strftime("%Y-%m-%dT%H:%M:%SZ"), t)
        # OMM keeps full precision; the TLE text rounds the elements (≈ 10 m here)
        np.testing.assert_allclose(r, want, atol=200.0, err_msg=kind)


def test_bad_element_files_name_the_line(tmp_path):
    (l1, l2), _ = _lines(90001)
    f = tmp_path / "bad.tle"
    f.write_text(f"SAT\n{l1[:-1]}{(int(l1[-1]) + 1) % 10}\n{l2}\n")
    with pytest.raises(InputError, match="line 2.*checksum"):
        load_element_sets(f)
    f.write_text(f"SAT\n{l1}\n")
    with pytest.raises(InputError, match="line 2"):
        load_element_sets(f)
    f.write_text('[{"OBJECT_NAME": "X", "NORAD_CAT_ID": 5}]')
    with pytest.raises(InputError, match="missing OMM field"):
        load_element_sets(f)
    f.write_text('<!DOCTYPE x [<!ENTITY a "b">]><ndm/>')
    with pytest.raises(InputError, match="DOCTYPE"):
        load_element_sets(f)
    f.write_text(f"{l1}\n{l2}\n")
    with pytest.raises(InputError, match="no element set for this object"):
        find_element_set(load_element_sets(f), "ISS")
    fifo = tmp_path / "fifo.tle"
    os.mkfifo(fifo)
    msg = G.refused_without_blocking(load_element_sets, fifo)
    assert msg.startswith("InputError") and "not a regular" in msg


def test_old_elements_warn():
    (l1, l2), _ = _lines(90001)
    import tempfile

    with tempfile.NamedTemporaryFile("w", suffix=".tle", delete=False) as fh:
        fh.write(f"{l1}\n{l2}\n")
    es = load_element_sets(fh.name)[0]
    os.unlink(fh.name)
    assert check_element_age(es, [EPOCH + timedelta(days=2)]) == pytest.approx(2.0)
    with pytest.warns(ElementAgeWarning, match="10.0 days"):
        check_element_age(es, [EPOCH + timedelta(days=10)])


def test_passes_match_a_brute_force_skyfield_search(tmp_path):
    """Every reported pass contains visible samples of an independent 20 s grid search
    (skyfield altaz ≥ 10°, is_sunlit on DE421, Sun altitude < −12°), and every visible grid
    sample lies inside a reported visible interval (within one grid step)."""
    from skyfield.api import EarthSatellite, wgs84

    (l1, l2), _ = _lines(90001, a_km=6378.137 + 550.0, i=53.0, raan=100.0)
    (m1, m2), _ = _lines(90002, a_km=6378.137 + 800.0, i=97.6, raan=60.0)
    f = tmp_path / "e.tle"
    f.write_text(f"ONE\n{l1}\n{l2}\nTWO\n{m1}\n{m2}\n")
    out = tmp_path / "passes.csv"
    assert main(["passes", str(f), "--site", "32.4434,-110.7881,2791", "--from",
                 "2022-03-21T00:00:00Z", "--to", "2022-03-22T00:00:00Z", "-o", str(out), "-q"]) == 0
    import csv

    rows = list(csv.DictReader(out.open()))
    assert rows, "no visible pass found in a day of two LEO objects"
    ts, eph = G.skyfield()
    topos = wgs84.latlon(32.4434, -110.7881, elevation_m=2791)
    step = 20.0
    grid = [EPOCH.replace(hour=0) + timedelta(seconds=s) for s in np.arange(0, 86400, step)]
    t = ts.from_datetimes(grid)
    sun_alt = (eph["earth"] + topos).at(t).observe(eph["sun"]).apparent().altaz()[0].degrees
    parse = (lambda s: datetime.fromisoformat(s.replace("Z", "+00:00")))
    for name, a, b in (("ONE", l1, l2), ("TWO", m1, m2)):
        sat = EarthSatellite(a, b, name, ts=ts)
        alt = (sat - topos).at(t).altaz()[0].degrees
        lit = sat.at(t).is_sunlit(eph)
        vis = (alt >= 10.0) & lit & (sun_alt < -12.0)
        mine = [(parse(r["visible_start_utc"]), parse(r["visible_end_utc"])) for r in rows
                if r["object"] == name]
        for k in np.flatnonzero(vis):
            assert any(s - timedelta(seconds=step) <= grid[k] <= e + timedelta(seconds=step)
                       for s, e in mine), (name, grid[k])
        for s, e in mine:
            inside = [vis[k] for k, g in enumerate(grid) if s <= g <= e]
            assert not inside or any(inside) or (e - s).total_seconds() < step, (name, s, e)


def test_an_object_above_the_horizon_all_day_is_one_pass(tmp_path):
    """A geostationary object (a = 42 164 km, i ≈ 0) over Arizona has no rise or set: one pass
    spanning the search, whose visible part is the night (skyfield: find_events finds nothing)."""
    from lightcurve.cli.recordings import find_passes
    from lightcurve.geometry.sites import get_site

    (l1, l2), _ = _lines(91111, a_km=42164.0, e=1e-4, i=0.05, raan=0.0, argp=0.0, M=90.0)
    f = tmp_path / "geo.tle"
    f.write_text(f"GEO\n{l1}\n{l2}\n")
    rows = find_passes(load_element_sets(f), get_site("mount_lemmon"), EPOCH,
                       EPOCH + timedelta(days=1), step_s=60.0)
    assert len(rows) == 1 and rows[0]["rise_utc"] == "2022-03-21T02:00:00Z"
    assert rows[0]["set_utc"] == "2022-03-22T02:00:00Z" and rows[0]["max_elevation_deg"] > 10
    assert 4 * 3600 < rows[0]["visible_s"] < 14 * 3600     # one night, not the whole day
    with pytest.raises(InputError, match="--step-s"):
        find_passes(load_element_sets(f), get_site("mount_lemmon"), EPOCH,
                    EPOCH + timedelta(days=1), step_s=0.05)
