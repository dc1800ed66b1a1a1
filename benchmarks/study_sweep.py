"""Shared by the sweep benchmarks (``bernard_ukf_alpha.py``, ``bernard_bpf_open.py``): a study
TOML derived from a stored one, and one ``lightcurve compare`` run of it.

* :func:`derived_text` — the study's text under a new ``[study] name``, with its relative paths
  (``scenario``, ``thesis_table``) made absolute so that the text can live in a temporary
  folder; the caller then edits the settings it sweeps.
* :func:`run_derived` — write that text to a temporary file, run ``lightcurve compare`` on it
  into ``out`` (resuming the runs stored there) and return the parsed ``summary.json``.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path


def derived_text(base: Path, name: str) -> str:
    """The text of the study TOML ``base`` named ``name``, relative paths made absolute."""
    txt = base.read_text(encoding="utf-8")

    def absolute(m):
        return f'{m.group(1)} = "{(base.parent / m.group(2)).resolve().as_posix()}"'

    txt = re.sub(r'^(thesis_table|scenario) = "([^"]+)"', absolute, txt, flags=re.M)
    return re.sub(r'^name = "[^"]+"', f'name = "{name}"', txt, count=1, flags=re.M)


def run_derived(text: str, out: Path, *, workers: int, runs: int | None = None) -> dict:
    """Run the study ``text`` with ``lightcurve compare -o out --workers workers -q`` (and
    ``--runs runs``); return its summary.json. A failing command raises CalledProcessError."""
    with tempfile.TemporaryDirectory() as td:
        toml = Path(td) / f"{out.name}.toml"
        toml.write_text(text, encoding="utf-8")
        cmd = [sys.executable, "-m", "lightcurve", "compare", str(toml), "-o", str(out),
               "--workers", str(workers), "-q"]
        if runs:
            cmd += ["--runs", str(runs)]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.loads((out / "summary.json").read_text(encoding="utf-8"))
