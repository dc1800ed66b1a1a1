"""The output folder of a resumable Monte Carlo study (lightcurve and CSS studies alike):
``study.json`` (what was run), ``runs/`` (one file per finished run), ``summary.json`` and
``report.html``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from .atomic import clean_stale_temp
from .safe_open import read_text

__all__ = ["read_study_meta", "open_runs_folder"]


def read_study_meta(meta: Path) -> dict:
    """The stored ``study.json`` as a dict (``{}`` when it is not a JSON object); the folder's
    own state file, but in a user-chosen folder: read as a regular file only."""
    text = read_text(meta, max_bytes=256 * 1024 * 1024, what="study.json", track=False)
    try:
        doc = json.loads(text)
    except ValueError:
        return {}
    return doc if isinstance(doc, dict) else {}


def open_runs_folder(out: Path, discard: bool) -> Path:
    """Create ``out/runs`` and return it; with ``discard`` the stored runs, summary and report
    of another study are deleted first. Temporary files of killed runs are removed (never a
    live writer's: :mod:`lightcurve.io.atomic`)."""
    runs = out / "runs"
    if discard:
        shutil.rmtree(runs, ignore_errors=True)
        for f in ("summary.json", "report.html"):
            (out / f).unlink(missing_ok=True)
    runs.mkdir(parents=True, exist_ok=True)
    clean_stale_temp(runs)
    return runs
