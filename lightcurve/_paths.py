"""Locations of the bundled data folders (shapes, observatories, pipelines).

In a wheel install they live in ``lightcurve/_data/<name>`` (hatch ``force-include``); in a
source checkout or an editable install they are the top-level folders of the repository.
"""

from __future__ import annotations

from pathlib import Path

_PKG = Path(__file__).resolve().parent

__all__ = ["data_dir", "shared_data_dir"]


def data_dir(name: str) -> Path:
    """Return the bundled data folder ``name`` ('shapes', 'observatories' or 'pipelines')."""
    if name not in ("shapes", "observatories", "pipelines"):
        raise ValueError(f"unknown data folder {name!r}; allowed: shapes, observatories, pipelines")
    for cand in (_PKG / "_data" / name, _PKG.parent / name):
        if cand.is_dir():
            return cand
    raise FileNotFoundError(f"bundled data folder '{name}' not found next to {_PKG}")


def shared_data_dir() -> Path | None:
    """Return ``../shared/data`` beside the repository (or $LIGHTCURVE_SHARED_DATA), or None."""
    import os

    env = os.environ.get("LIGHTCURVE_SHARED_DATA")
    if env:
        p = Path(env)
        return p if p.is_dir() else None
    for base in (_PKG.parent, Path.cwd()):
        p = base.parent / "shared" / "data"
        if p.is_dir():
            return p
    return None
