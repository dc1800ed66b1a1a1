"""Measurement schedules: which site measures at which epoch.

A schedule is a pair of arrays ``(t (N,), site_index (N,))`` sorted by time then site. The
epochs lie on a fixed cadence grid ``t_k = k · cadence_s`` (k = 0, 1, …, ``t_k <= duration_s``);
an epoch belongs to a site when it falls inside one of that site's closed windows
``[t0, t1]`` (seconds since the scenario epoch). When windows of two sites overlap both sites
measure at the shared epochs (two rows with the same ``t``).

The grid is built from integer multiples of the cadence (no accumulated rounding), and the
window tests use a tolerance of 1e-9 · cadence so that ``t1 = 100`` with a 5 s cadence
includes 100 even when 100 is not exactly representable as k·cadence in floating point.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["DEFAULT_CADENCE_S", "BERNARD_SWITCHING_WINDOWS", "cadence_grid", "build_schedule",
           "bernard_switching_windows", "bernard_switching_schedule", "windows_from_flags"]

DEFAULT_CADENCE_S = 5.0
"""Default measurement cadence (Bernard 2021 ch. 9: one magnitude every 5 s)."""

BERNARD_SWITCHING_WINDOWS = (
    ((105.0, 200.0), (300.0, 400.0)),  # site 1 (index 0)
    ((0.0, 100.0), (205.0, 260.0)),    # site 2 (index 1)
)
"""Bernard (2021) two-site switching pattern: site 1 at 105–200 s and 300–400 s, site 2 at
0–100 s and 205–260 s (seconds since the scenario epoch)."""


def cadence_grid(duration_s: float, cadence_s: float = DEFAULT_CADENCE_S) -> np.ndarray:
    """Epochs ``k · cadence_s`` for k = 0 … floor(duration_s / cadence_s) (inclusive end), s."""
    if not (np.isfinite(duration_s) and duration_s >= 0):
        raise InputError("duration must be finite and >= 0", field="duration_s", value=duration_s)
    if not (np.isfinite(cadence_s) and cadence_s > 0):
        raise InputError("cadence must be finite and > 0", field="cadence_s", value=cadence_s)
    n = int(np.floor(duration_s / cadence_s * (1 + 1e-12) + 1e-9)) + 1
    if n > 50_000_000:
        raise InputError("too many epochs", field="cadence_s", value=cadence_s,
                         allowed="duration_s / cadence_s <= 5e7")
    return np.arange(n, dtype=float) * cadence_s


def build_schedule(duration_s: float, cadence_s: float = DEFAULT_CADENCE_S,
                   windows_per_site=None):
    """Epochs and site indices of a one- or multi-site observation.

    Parameters
    ----------
    duration_s : float
        Length of the scenario (s); the grid runs from 0 to ``duration_s`` inclusive.
    cadence_s : float
        Grid step (s), default 5 s.
    windows_per_site : list (one per site) of lists of ``(t0, t1)`` pairs, seconds
        Closed observing windows of site 0, site 1, …; ``None`` means one site observing the
        whole time.

    Returns
    -------
    t : (N,) float, s — sorted; site_index : (N,) int — sorted within equal ``t``.
    """
    grid = cadence_grid(duration_s, cadence_s)
    if windows_per_site is None:
        windows_per_site = [[(0.0, float(duration_s))]]
    tol = 1e-9 * cadence_s
    ts, idx = [], []
    for k, windows in enumerate(windows_per_site):
        mask = np.zeros(grid.size, dtype=bool)
        for w in windows:
            try:
                t0, t1 = (float(x) for x in w)
            except (TypeError, ValueError):
                raise InputError("a window must be a pair (t0, t1) of seconds",
                                 field=f"windows[{k}]", value=w) from None
            if not (np.isfinite(t0) and np.isfinite(t1)):
                raise InputError("window times must be finite", field=f"windows[{k}]",
                                 value=(t0, t1), allowed="finite seconds, t0 <= t1")
            if t1 < t0:
                raise InputError("window end before its start", field=f"windows[{k}]",
                                 value=(t0, t1), allowed="t0 <= t1")
            mask |= (grid >= t0 - tol) & (grid <= t1 + tol)
        ts.append(grid[mask])
        idx.append(np.full(int(mask.sum()), k, dtype=np.int64))
    t = np.concatenate(ts) if ts else np.empty(0)
    site = np.concatenate(idx) if idx else np.empty(0, dtype=np.int64)
    order = np.lexsort((site, t))
    return t[order], site[order]


def bernard_switching_windows():
    """Bernard's (2021) two-site windows as lists, ``[[site-1 windows], [site-2 windows]]``."""
    return [list(w) for w in BERNARD_SWITCHING_WINDOWS]


def bernard_switching_schedule(cadence_s: float = DEFAULT_CADENCE_S, duration_s: float = 400.0):
    """Schedule of Bernard's switching pattern (site 1 → index 0, site 2 → index 1)."""
    return build_schedule(duration_s, cadence_s, bernard_switching_windows())


def windows_from_flags(t_s, flags):
    """Contiguous runs of ``True`` in ``flags`` as ``[(t_first, t_last), …]`` (seconds).

    ``t_s`` must be sorted; useful to turn per-epoch visibility into observing windows.
    """
    t = np.asarray(t_s, dtype=float)
    f = np.asarray(flags, dtype=bool)
    if t.shape != f.shape:
        raise ValueError("t_s and flags must have the same shape")
    if f.size == 0:
        return []
    d = np.diff(f.astype(np.int8))
    starts = list(np.flatnonzero(d == 1) + 1)
    ends = list(np.flatnonzero(d == -1))
    if f[0]:
        starts.insert(0, 0)
    if f[-1]:
        ends.append(f.size - 1)
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends)]
