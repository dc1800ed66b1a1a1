"""TOML validation messages name the file, the key and the allowed range."""

import pytest

from lightcurve import InputError
from lightcurve.io.tomlio import Section, load_toml


def test_syntax_error_names_file_and_line(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text("[orbit]\na_km = = 3\n")
    with pytest.raises(InputError, match=r"s\.toml.*line 2"):
        load_toml(p)


def test_range_and_unknown_keys(tmp_path):
    sec = Section({"e": 1.5, "a_kmm": 7000.0}, file="x.toml", name="orbit")
    with pytest.raises(InputError) as exc:
        sec.float("e", min=0.0, max=1.0, max_open=True)
    msg = str(exc.value)
    assert "x.toml" in msg and "orbit.e" in msg and "1.5" in msg and "[0.0, 1.0)" in msg
    sec2 = Section({"a_kmm": 7000.0}, file="x.toml", name="orbit")
    sec2.float("a_km", 7000.0)
    with pytest.raises(InputError, match="a_kmm"):
        sec2.check_unknown()


def test_types():
    sec = Section({"n": True, "v": [1, 2], "s": "J9"}, name="t")
    with pytest.raises(InputError, match="number"):
        sec.float("n")
    with pytest.raises(InputError, match="3 numbers"):
        sec.vector("v", n=3)
    with pytest.raises(InputError, match="J2"):
        sec.str("s", choices=("point", "J2", "J4"))
    with pytest.raises(InputError, match="missing"):
        sec.float("absent")
