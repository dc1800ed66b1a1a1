"""docs/architecture.md: every function of the equation table exists and its docstring cites the
equation of its row (the number in the function's docstring; the author there or in its
module's docstring)."""

from __future__ import annotations

import importlib
import inspect
import re
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[1] / "docs" / "architecture.md"
ROW = re.compile(r"^\| *((Bernard|O'Keefe) (eq\.|§|table) *([0-9A-Z][0-9.]*)) *\| *(.+?) *\| *`([\w.]+)` *\|$")


def _rows():
    rows = [ROW.match(line.strip()) for line in DOC.read_text(encoding="utf-8").splitlines()]
    return [m for m in rows if m]


def test_table_is_there_and_covers_both_theses():
    rows = _rows()
    assert len(rows) >= 40
    assert {m.group(2) for m in rows} == {"Bernard", "O'Keefe"}
    # the core's central pieces are all listed
    names = {m.group(6) for m in rows}
    for f in ("lightcurve.core.dynamics.rk4_step_xyz", "lightcurve.core.rotations.q2grp_xyz",
              "lightcurve.core.photometry.cook_torrance_xyz",
              "lightcurve.core.kalman.joseph_apply_nb"):
        assert f in names


@pytest.mark.parametrize("row", _rows(), ids=lambda m: f"{m.group(1)}-{m.group(6).rsplit('.', 1)[1]}")
def test_function_exists_and_cites_its_equation(row):
    author, kind, number, dotted = row.group(2), row.group(3), row.group(4), row.group(6)
    module_name, func_name = dotted.rsplit(".", 1)
    module = importlib.import_module(module_name)
    func = getattr(module, func_name)
    doc = inspect.getdoc(getattr(func, "py_func", func)) or ""
    # "eq. 3.28–3.30" cites 3.28; "eq. 3.8–3.13" cites 3.13: the number as a whole token
    assert re.search(rf"(?<![\d.]){re.escape(number)}(?![\d])", doc), (dotted, number, doc[:200])
    if kind == "§":
        assert "§" + number in doc
    assert author in doc or author in (inspect.getdoc(module) or ""), (dotted, author)
