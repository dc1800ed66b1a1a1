"""docs/robustness.md stays in sync with the hardening tests: its table of every
bad-input case handled and how lists exactly the hardening tests (each listed test exists,
each test is listed)."""

from __future__ import annotations

import re
from pathlib import Path

HERE = Path(__file__).resolve().parent
DOC = HERE.parents[1] / "docs" / "robustness.md"
REF = re.compile(r"`(test_hardening_[a-z0-9_]+\.py)::(test_[a-z0-9_]+)`")


def _listed():
    rows = [ln for ln in DOC.read_text(encoding="utf-8").splitlines() if ln.startswith("|")]
    refs = [m.groups() for ln in rows for m in REF.finditer(ln)]
    assert len(refs) >= 40, "the robustness table lists suspiciously few tests"
    return refs


def _defined():
    out = set()
    for f in HERE.glob("test_hardening_*.py"):
        for name in re.findall(r"^def (test_[a-z0-9_]+)\(", f.read_text(encoding="utf-8"), re.M):
            out.add((f.name, name))
    return out


def test_every_listed_test_exists():
    missing = sorted(set(_listed()) - _defined())
    assert not missing, f"docs/robustness.md names tests that do not exist: {missing}"


def test_every_hardening_test_is_listed():
    unlisted = sorted(_defined() - set(_listed()))
    assert not unlisted, f"hardening tests missing from docs/robustness.md: {unlisted}"


def test_dask_trust_model_is_stated():
    """The --scheduler trust model is stated honestly: Dask pickles both ways."""
    text = DOC.read_text(encoding="utf-8")
    sec = text[text.index("## Dask: what `--scheduler` trusts"):]
    sec = sec[: sec.index("\n## ", 5)]
    for frag in ("pickle", "arbitrary code", "--scheduler", "tls://", "--dask-local"):
        assert frag in sec, frag
    # ... and where the option is offered: the --help of every command with --scheduler
    import argparse

    from lightcurve.cli import build_parser

    def helps(parser):
        for a in parser._actions:
            if isinstance(a, argparse._SubParsersAction):
                for sub in a.choices.values():
                    yield from helps(sub)
            elif "--scheduler" in a.option_strings:
                yield parser.prog, " ".join((a.help or "").split())

    found = list(helps(build_parser()))
    assert len(found) >= 3, found  # compare, invert, css study
    for prog, text in found:
        assert "pickles" in text and "run code in this process" in text, (prog, text)
