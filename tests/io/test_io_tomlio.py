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


def test_typed_overrides_types_text_and_errors():
    """One checker for every ablation table: dataclass field types (as annotations are
    strings under ``from __future__ import annotations``), command-line strings parsed only
    with ``from_text``, and a one-line error naming the file, the dotted field, the value and
    what is allowed."""
    from dataclasses import dataclass

    from lightcurve.errors import InputError
    from lightcurve.io.tomlio import field_types, typed_overrides

    @dataclass
    class P:
        a: float = 1.0
        b: bool = False
        n: int = 2
        rule: str = "x"

    types = field_types(P)
    assert typed_overrides({"a": 2, "b": True, "n": 3, "rule": "y"}, types, field="f",
                           choices={"rule": ("x", "y")}) == {"a": 2.0, "b": True, "n": 3,
                                                             "rule": "y"}
    assert typed_overrides({"a": "0.5", "b": "TRUE", "n": "4"}, types, field="f",
                           from_text=True) == {"a": 0.5, "b": True, "n": 4}
    cases = [({"c": 1}, "f.c", "unknown"), ({"b": "true"}, "f.b", "true or false"),
             ({"b": 1.5}, "f.b", "true or false"), ({"n": 0}, "f.n", ">= 1"),
             ({"a": -1.0}, "f.a", ">= 0"), ({"a": float("nan")}, "f.a", ">= 0"),
             ({"a": True}, "f.a", ">= 0"), ({"rule": "z"}, "f.rule", "x, y")]
    for values, field, text in cases:
        with pytest.raises(InputError) as e:
            typed_overrides(values, types, field="f", file="s.toml",
                            choices={"rule": ("x", "y")})
        msg = str(e.value)
        assert "s.toml" in msg and field in msg and text in msg and "\n" not in msg
