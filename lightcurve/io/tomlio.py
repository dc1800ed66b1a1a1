"""TOML loading with validation that names the file, the key and the allowed range.

Usage::

    doc = load_toml("scenario.toml")          # InputError on a syntax error (line/column)
    orbit = Section(doc, file="scenario.toml").section("orbit")
    a_km = orbit.float("a_km", min=6378.137)
    kind = orbit.str("type", choices=("keplerian", "cartesian", "tle"), default="keplerian")
    orbit.check_unknown()                     # a misspelt key is an error, not silently ignored
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np

from ..errors import InputError
from .safe_open import TOML_MAX_BYTES as MAX_TOML_BYTES

__all__ = ["load_toml", "loads_toml", "read_toml_text", "Section", "REQUIRED", "field_types",
           "typed_overrides"]

REQUIRED = object()


def loads_toml(text: str, file="<string>") -> dict:
    """Parse TOML text; a syntax error becomes an :class:`InputError` naming the file and line.

    Nesting deeper than Python's recursion limit (``a = [[[[…]]]]`` 5,000 deep) is refused
    the same way (tomllib parses arrays and inline tables recursively).
    """
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", file=file) from None
    except RecursionError:
        raise InputError("not valid TOML: arrays or tables nested too deeply", file=file,
                         allowed="nesting well below 1000 levels") from None


def read_toml_text(path) -> str:
    """The text of a TOML file: a regular file (no FIFO or device) of at most 20 MiB, UTF-8
    (:mod:`lightcurve.io.safe_open`)."""
    from .safe_open import read_text

    return read_text(path, max_bytes=MAX_TOML_BYTES, what="TOML file")


def load_toml(path, *, with_text: bool = False):
    """Read and parse a TOML file (regular file, UTF-8, at most 20 MiB).

    With ``with_text`` returns ``(document, text)``: the text that was parsed (read once, so
    the two always agree).
    """
    text = read_toml_text(path)
    doc = loads_toml(text, file=Path(path))
    return (doc, text) if with_text else doc


class Section:
    """A validated view of one TOML table.

    Parameters
    ----------
    data : dict
        The parsed table.
    file : path-like, optional
        File it came from (for messages).
    name : str
        Dotted name of the table (``"orbit"``, ``"sites[1]"``) used in messages.
    """

    def __init__(self, data, file=None, name: str = ""):
        if not isinstance(data, dict):
            raise InputError("expected a table", file=file, field=name or None, value=data)
        self.data = data
        self.file = file
        self.name = name
        self._used: set[str] = set()

    # -- helpers -----------------------------------------------------------------------
    def field_name(self, key: str) -> str:
        """Dotted name of ``key`` in this table (``"orbit.e"``), for error messages."""
        return f"{self.name}.{key}" if self.name else key

    def _err(self, key, msg, value=None, allowed=None):
        return InputError(msg, file=self.file, field=self.field_name(key), value=value, allowed=allowed)

    def has(self, key: str) -> bool:
        """True when ``key`` is present."""
        return key in self.data

    def _get(self, key, default):
        self._used.add(key)
        if key in self.data:
            return self.data[key], True
        if default is REQUIRED:
            raise self._err(key, "missing required key")
        return default, False

    # -- typed getters -----------------------------------------------------------------
    def float(self, key, default=REQUIRED, *, min=None, max=None, min_open=False, max_open=False):
        """A finite real number within [min, max] (open ends with ``min_open``/``max_open``)."""
        v, present = self._get(key, default)
        if not present:
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self._err(key, "expected a number", v)
        v = float(v)
        if not math.isfinite(v):
            raise self._err(key, "expected a finite number", v)
        self._check_range(key, v, min, max, min_open, max_open)
        return v

    def int(self, key, default=REQUIRED, *, min=None, max=None):
        """An integer within [min, max]."""
        v, present = self._get(key, default)
        if not present:
            return v
        if isinstance(v, bool) or not isinstance(v, int):
            raise self._err(key, "expected an integer", v)
        self._check_range(key, v, min, max, False, False)
        return v

    def bool(self, key, default=REQUIRED):
        """A boolean (true/false)."""
        v, present = self._get(key, default)
        if present and not isinstance(v, bool):
            raise self._err(key, "expected true or false", v)
        return v

    def str(self, key, default=REQUIRED, *, choices=None):
        """A string, optionally one of ``choices``."""
        v, present = self._get(key, default)
        if not present:
            return v
        if not isinstance(v, str):
            raise self._err(key, "expected a string", v)
        if choices is not None and v not in choices:
            raise self._err(key, "unknown value", v, allowed=", ".join(map(str, choices)))
        return v

    def vector(self, key, default=REQUIRED, *, n=None, min=None, max=None, min_open=False,
               max_open=False):
        """A list of finite numbers of length ``n`` (any length if None) as a float array."""
        v, present = self._get(key, default)
        if not present:
            return None if v is None else np.asarray(v, dtype=float)
        if not isinstance(v, list) or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v):
            raise self._err(key, "expected a list of numbers", v)
        if n is not None and len(v) != n:
            raise self._err(key, f"expected {n} numbers, got {len(v)}", v)
        arr = np.asarray(v, dtype=float)
        if not np.all(np.isfinite(arr)):
            raise self._err(key, "expected finite numbers", v)
        for x in arr:
            self._check_range(key, x, min, max, min_open, max_open)
        return arr

    def matrix(self, key, default=REQUIRED, *, shape=None):
        """A list of lists of finite numbers as a 2-D float array with optional ``shape``."""
        v, present = self._get(key, default)
        if not present:
            return None if v is None else np.asarray(v, dtype=float)
        try:
            arr = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise self._err(key, "expected a list of lists of numbers", v) from None
        if arr.ndim != 2 or (shape is not None and any(s is not None and s != t for s, t in zip(shape, arr.shape))):
            raise self._err(key, f"expected a matrix of shape {shape}", v)
        if not np.all(np.isfinite(arr)):
            raise self._err(key, "expected finite numbers", v)
        return arr

    def section(self, key, default=REQUIRED) -> "Section | None":
        """A sub-table as a :class:`Section` (None if absent and default is None)."""
        v, present = self._get(key, default)
        if not present:
            return None if v is None else Section(v, self.file, self.field_name(key))
        if not isinstance(v, dict):
            raise self._err(key, "expected a table", v)
        return Section(v, self.file, self.field_name(key))

    def sections(self, key, default=REQUIRED) -> list["Section"]:
        """An array of tables (``[[key]]``) as a list of :class:`Section`."""
        v, present = self._get(key, default)
        if not present:
            return [] if v is None else v
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            raise self._err(key, "expected an array of tables ([[...]])", v)
        return [Section(x, self.file, f"{self.field_name(key)}[{i}]") for i, x in enumerate(v)]

    def raw(self, key, default=REQUIRED):
        """The value as parsed, unvalidated (the caller validates)."""
        v, _ = self._get(key, default)
        return v

    def check_unknown(self, extra_allowed=()) -> None:
        """Raise if the table has keys that no getter asked for (catches misspellings)."""
        unknown = [k for k in self.data if k not in self._used and k not in extra_allowed]
        if unknown:
            known = sorted(self._used | set(extra_allowed))
            raise InputError(
                f"unknown key(s) {', '.join(repr(k) for k in unknown)}",
                file=self.file,
                field=self.name or None,
                allowed=", ".join(known) if known else "no keys",
            )

    def _check_range(self, key, v, lo, hi, lo_open, hi_open):
        bad = (lo is not None and (v < lo or (lo_open and v == lo))) or (
            hi is not None and (v > hi or (hi_open and v == hi))
        )
        if bad:
            left = "(" if lo_open else "["
            right = ")" if hi_open else "]"
            allowed = f"{left}{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}{right}"
            raise self._err(key, "value out of range", v, allowed=allowed)


def field_types(cls, exclude=()) -> dict:
    """Name → type of the fields of dataclass ``cls`` (except ``exclude``), for
    :func:`typed_overrides`."""
    from dataclasses import fields

    return {f.name: f.type for f in fields(cls) if f.name not in exclude}


_TYPE_NAMES = {bool: "bool", int: "int", float: "float", str: "str"}


def typed_overrides(values, types: dict, *, field: str, file=None, what="parameter",
                    choices=None, from_text=False, int_min=1) -> dict:
    """Check a table of setting overrides (an ablation: ``[robust_filter]`` of a study file,
    ``--thesis-filter NAME=VALUE`` on the command line) against ``types`` (name → bool, int,
    float or str, or their names as strings: :func:`field_types` of a dataclass) and return
    them with those types.

    bool: true/false (with ``from_text``, also the strings "true", "false", "1", "0");
    int: an integer ≥ ``int_min``; float: a finite number ≥ 0; str: one of ``choices[name]``.
    Values from a TOML file must already have their type; with ``from_text`` (command-line
    strings) they are parsed.  Raises :class:`InputError` naming ``file``, ``field.name``,
    the value and what is allowed.
    """
    choices = choices or {}
    out = {}
    for k, v in dict(values or {}).items():
        name = f"{field}.{k}"
        if k not in types:
            raise InputError(f"unknown {what}", file=file, field=name, value=v,
                             allowed=", ".join(types))
        t = types[k]
        t = _TYPE_NAMES.get(t, t)
        if isinstance(t, str) and t.endswith(" | None"):   # optional field: None = automatic
            t = t[:-len(" | None")]
        if t == "bool":
            if from_text and isinstance(v, str) and v.lower() in ("true", "false", "1", "0"):
                v = v.lower() in ("true", "1")
            if not isinstance(v, bool):
                raise InputError("expected true or false", file=file, field=name, value=v,
                                 allowed="true, false")
            out[k] = v
        elif t == "int":
            if from_text and isinstance(v, str):
                try:
                    v = int(v)
                except ValueError:
                    pass
            if isinstance(v, bool) or not isinstance(v, int) or v < int_min:
                raise InputError("expected an integer", file=file, field=name, value=v,
                                 allowed=f">= {int_min}")
            out[k] = v
        elif t == "str":
            allowed = tuple(choices.get(k, ()))
            if not isinstance(v, str) or (allowed and v not in allowed):
                raise InputError("unknown value", file=file, field=name, value=v,
                                 allowed=", ".join(allowed) or "a string")
            out[k] = v
        else:
            if from_text and isinstance(v, str):
                try:
                    v = float(v)
                except ValueError:
                    pass
            if isinstance(v, bool) or not isinstance(v, (int, float)) \
                    or not math.isfinite(v) or v < 0:
                raise InputError("expected a finite non-negative number", file=file,
                                 field=name, value=v, allowed=">= 0")
            out[k] = float(v)
    return out
