"""Shared helpers of the hardening fuzz tests: the "only InputError escapes" check, a tiny TOML
writer for mutated documents, and hypothesis strategies for hostile values and bytes.

Every fuzz test counts its generated cases in ``CASES`` (loader -> number of calls); the
``test_hardening_zz_case_counts`` test at the end of the suite prints the table (the count
quoted in docs/robustness.md).
"""

from __future__ import annotations

import atexit
import json
import math
import os
import shutil
import tempfile
from collections import Counter
from pathlib import Path

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from lightcurve.errors import InputError

#: loader name -> number of generated inputs fed to it in this pytest session
CASES: Counter = Counter()

#: every fuzz file lives under one folder, removed when the test session ends
_TMP_ROOT = tempfile.mkdtemp(prefix="lc-hardening-")
atexit.register(shutil.rmtree, _TMP_ROOT, True)


def new_tmp_dir(prefix: str = "case-") -> Path:
    """A fresh folder for one generated case (hypothesis examples cannot use tmp_path)."""
    return Path(tempfile.mkdtemp(prefix=prefix, dir=_TMP_ROOT))

#: common settings: bounded examples, no per-example deadline flakiness on a loaded 2-core
#: machine (each loader call is additionally bounded by the refusal of huge sizes)
FUZZ = dict(deadline=None, derandomize=True, database=None,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                   HealthCheck.data_too_large])


def fuzz_settings(n: int):
    """Hypothesis settings with ``n`` examples (derandomized: the same cases every run)."""
    return settings(max_examples=n, **FUZZ)


def only_input_error(loader: str, fn, *args, file=None, **kw):
    """Call ``fn``; return its result, or the :class:`InputError` it raised.

    Any other exception propagates (the test fails with it). When ``file`` is given, an
    InputError must name it (its path or its name appears in the message).
    """
    CASES[loader] += 1
    try:
        return fn(*args, **kw)
    except InputError as exc:
        if file is not None:
            text = str(exc)
            assert str(file) in text or os.path.basename(str(file)) in text, \
                f"InputError does not name the file {file}: {text}"
        return exc


# ----------------------------------------------------------------------------------------
# TOML writer (enough for mutated documents: tables, arrays of tables, scalars, arrays)
# ----------------------------------------------------------------------------------------
def _key(k: str) -> str:
    return json.dumps(str(k), ensure_ascii=False)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def dumps_toml(doc: dict) -> str:
    """Serialise a dict to TOML text (tables as [a."b"], lists of dicts as [[...]])."""
    lines: list[str] = []

    def table(d: dict, path: list[str]):
        scal = {k: v for k, v in d.items()
                if not isinstance(v, dict) and not (isinstance(v, list) and v and all(isinstance(x, dict) for x in v))}
        for k, v in scal.items():
            lines.append(f"{_key(k)} = {_value(v)}")
        for k, v in d.items():
            if k in scal:
                continue
            p = path + [_key(k)]
            if isinstance(v, dict):
                lines.append(f"\n[{'.'.join(p)}]")
                table(v, p)
            else:
                for item in v:
                    lines.append(f"\n[[{'.'.join(p)}]]")
                    table(item, p)

    table(doc, [])
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------
# strategies
# ----------------------------------------------------------------------------------------
HOSTILE_FLOATS = st.sampled_from([0.0, -0.0, -1.0, 1e-320, 1e308, -1e308, float("nan"),
                                  float("inf"), float("-inf"), 1e19, 360.0, 361.0, -91.0, 0.5])
HOSTILE_TEXT = st.sampled_from(["", " ", "nan", "inf", "-inf", "NaN", "1e999", "../../etc/passwd",
                                "\u202eevil", "名前", "\x7f", "a" * 5000, "None", "__import__('os')",
                                "!!python/object:os.system", "0x10", "1_000", "2020-13-45T25:61:61Z"])
SCALARS = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    HOSTILE_FLOATS,
    st.text(max_size=30),
    HOSTILE_TEXT,
)
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                       st.dictionaries(st.text(max_size=8), inner, max_size=3)),
                      max_leaves=8)


def key_paths(doc, prefix=()):
    """All key paths (tuples) of a nested dict/list document."""
    out = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.append(prefix + (k,))
            out.extend(key_paths(v, prefix + (k,)))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            if isinstance(v, dict):
                out.extend(key_paths(v, prefix + (i,)))
    return out


def mutate(doc, path, value, delete=False):
    """Deep-copied ``doc`` with the item at ``path`` replaced by ``value`` (or deleted)."""
    import copy

    d = copy.deepcopy(doc)
    cur = d
    for k in path[:-1]:
        cur = cur[k]
    if delete:
        del cur[path[-1]]
    else:
        cur[path[-1]] = value
    return d


@st.composite
def mutated_docs(draw, base: dict):
    """A document derived from ``base``: 1-3 keys replaced by hostile values, deleted, or an
    unknown key added."""
    doc = base
    for _ in range(draw(st.integers(1, 3))):
        paths = key_paths(doc)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        action = draw(st.sampled_from(["replace", "replace", "delete", "add"]))
        if action == "delete":
            doc = mutate(doc, path, None, delete=True)
        elif action == "add":
            doc = mutate(doc, path[:-1] + (draw(st.text(min_size=1, max_size=6)),), draw(VALUES))
        else:
            doc = mutate(doc, path, draw(VALUES))
    return doc


@st.composite
def damaged_bytes(draw, good: bytes):
    """``good`` truncated, with bytes flipped, with a line dropped, or replaced by noise."""
    kind = draw(st.sampled_from(["truncate", "flip", "dropline", "random", "dupline"]))
    if kind == "truncate":
        return good[: draw(st.integers(0, max(len(good) - 1, 0)))]
    if kind == "flip":
        b = bytearray(good)
        for _ in range(draw(st.integers(1, 8))):
            if not b:
                break
            i = draw(st.integers(0, len(b) - 1))
            b[i] = draw(st.integers(0, 255))
        return bytes(b)
    if kind in ("dropline", "dupline"):
        lines = good.splitlines(keepends=True)
        if not lines:
            return good
        i = draw(st.integers(0, len(lines) - 1))
        if kind == "dropline":
            return b"".join(lines[:i] + lines[i + 1:])
        return b"".join(lines[: i + 1] + lines[i:])
    return draw(st.binary(max_size=400))


def small_curve(n=8):
    """A small valid two-site lightcurve with truth (built here, not simulated: fast)."""
    import numpy as np

    from lightcurve.io.lightcurve_h5 import Lightcurve

    rng = np.random.default_rng(0)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    r_obj = np.tile([7.0e6, 0.0, 0.0], (n, 1)) + rng.normal(scale=1e4, size=(n, 3))
    return Lightcurve(
        epoch_utc="2020-03-01T08:08:40Z", t=np.arange(n) * 5.0, mag=7 + rng.normal(size=n) * 0.1,
        mag_sigma=np.full(n, 0.02), site=np.arange(n) % 2, site_names=["socorro", "bear_lake"],
        site_lla_deg_m=np.array([[33.8, -106.7, 1500.0], [41.9, -111.4, 1800.0]]),
        r_obj_eci_m=r_obj, r_site_eci_m=np.tile([6.4e6, 0.0, 0.0], (n, 1)),
        r_sun_eci_m=np.tile([1.5e11, 0.0, 0.0], (n, 1)), lit_fraction=np.ones(n),
        elevation_rad=np.full(n, 0.5), truth_q=q, truth_omega_rad_s=rng.normal(size=(n, 3)) * 0.01,
        truth_mag=np.full(n, 7.0), scenario_toml="[scenario]\n", attrs={"shape": "cube_1u"})
