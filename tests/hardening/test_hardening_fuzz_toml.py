"""Fuzz: the TOML layer (load_toml, Section getters) and site files (load_sites/get_site).

Property: for any bytes or any parsed value, only InputError escapes, and its
message names the file.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardening_util import (VALUES, damaged_bytes, dumps_toml, fuzz_settings, mutated_docs,
                            new_tmp_dir, only_input_error)
from lightcurve import InputError
from lightcurve.io.tomlio import MAX_TOML_BYTES, Section, load_toml, loads_toml

GOOD_SITE = {"id": "fuzzsite", "name": "Fuzz", "lat_deg": 33.8, "lon_deg": -106.66,
             "height_m": 1500.0, "band": "V", "source": "test",
             "horizon_mask": {"az_deg": [0.0, 90.0, 180.0, 270.0], "alt_deg": [10.0, 15.0, 10.0, 5.0]}}


def _write(data: bytes, name="f.toml") -> Path:
    d = new_tmp_dir()
    p = d / name
    p.write_bytes(data)
    return p


@fuzz_settings(150)
@given(st.one_of(st.binary(max_size=300), damaged_bytes(dumps_toml(GOOD_SITE).encode())))
def test_load_toml_random_and_damaged_bytes(data):
    p = _write(data)
    out = only_input_error("load_toml", load_toml, p, file=p)
    assert isinstance(out, (dict, InputError))


@fuzz_settings(120)
@given(VALUES, st.sampled_from(["float", "int", "bool", "str", "vector", "matrix", "section",
                               "sections"]))
def test_section_getters_any_value(value, getter):
    sec = Section({"k": value}, file="fuzz.toml", name="tbl")
    fn = getattr(sec, getter)
    kw = {"n": 3} if getter == "vector" else {"shape": (3, 3)} if getter == "matrix" else {}
    if getter in ("float", "vector"):
        kw.update(min=0.0, max=10.0)
    only_input_error("Section getters", fn, "k", **kw, file="fuzz.toml")


def test_huge_toml_refused_early():
    """A sparse 1 GiB file is refused from its size, before reading (bounded time/memory)."""
    p = _write(b"", "huge.toml")
    with open(p, "r+b") as fh:
        fh.truncate(1 << 30)
    t0 = time.perf_counter()
    with pytest.raises(InputError, match=r"huge\.toml.*too large"):
        load_toml(p)
    assert time.perf_counter() - t0 < 5.0  # refused from stat(), never read (generous bound)
    assert MAX_TOML_BYTES < (1 << 30)


def test_toml_syntax_error_names_line_and_column():
    with pytest.raises(InputError) as exc:
        loads_toml('a = 1\nb = "x\n', file="s.toml")
    assert "s.toml" in str(exc.value) and "line 2" in str(exc.value)


def test_toml_not_utf8_names_byte():
    p = _write(b'a = "\xff\xfe"\n', "latin.toml")
    with pytest.raises(InputError, match=r"latin\.toml.*not UTF-8 text \(byte 5\)"):
        load_toml(p)


def test_toml_directory_and_missing():
    d = new_tmp_dir()
    (d / "dir.toml").mkdir()
    with pytest.raises(InputError, match="is a directory"):
        load_toml(d / "dir.toml")
    with pytest.raises(InputError, match="file not found"):
        load_toml(d / "missing.toml")


# ----------------------------------------------------------------------------------------
# site files
# ----------------------------------------------------------------------------------------
def _site_dir(text: bytes) -> tuple[Path, Path]:
    d = new_tmp_dir()
    f = d / "fuzzsite.toml"
    f.write_bytes(text)
    return d, f


@fuzz_settings(120)
@given(mutated_docs(GOOD_SITE))
def test_site_files_mutated(doc):
    d, f = _site_dir(dumps_toml(doc).encode())
    out = only_input_error("site TOML (load_sites)", __import__("lightcurve.geometry.sites",
                           fromlist=["load_sites"]).load_sites, [d], file=f)
    if not isinstance(out, InputError):
        s = out[doc.get("id", "fuzzsite")] if doc.get("id", "fuzzsite") in out else None
        assert s is not None
        assert -90 <= s.lat_deg <= 90 and -180 <= s.lon_deg < 360 and -500 <= s.height_m <= 9000


@fuzz_settings(60)
@given(damaged_bytes(dumps_toml(GOOD_SITE).encode()))
def test_site_files_damaged_bytes(data):
    from lightcurve.geometry.sites import load_sites

    d, f = _site_dir(data)
    only_input_error("site TOML (load_sites)", load_sites, [d], file=f)


@fuzz_settings(60)
@given(st.dictionaries(st.sampled_from(["lat_deg", "lon_deg", "height_m", "id", "name", "band",
                                       "horizon_mask", "extra"]), VALUES, max_size=6))
def test_inline_site_tables(table):
    """Inline [[sites]] tables (get_site with a dict): only InputError."""
    from lightcurve.geometry.sites import get_site

    only_input_error("inline site (get_site)", get_site, table)


def test_unknown_site_lists_known_ids():
    from lightcurve.geometry.sites import get_site

    with pytest.raises(InputError) as exc:
        get_site("atlantis")
    assert "unknown site" in str(exc.value) and "socorro" in str(exc.value)


def test_site_folder_missing():
    from lightcurve.geometry.sites import load_sites

    with pytest.raises(InputError, match="site folder not found"):
        load_sites([os.path.join(tempfile.gettempdir(), "no-such-site-folder-xyz")])
