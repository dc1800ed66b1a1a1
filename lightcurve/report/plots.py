"""Matplotlib figures of lightcurves (headless; the Agg backend is selected on import)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..io.atomic import atomic_path  # noqa: E402

__all__ = ["plot_lightcurve"]


def _spans(t, flag):
    """Contiguous [t_start, t_end] spans where ``flag`` is true, padded by half a step."""
    if len(t) == 0:
        return []
    step = np.median(np.diff(t)) if len(t) > 1 else 1.0
    half = 0.5 * step
    spans, start = [], None
    for i, f in enumerate(flag):
        gap = i > 0 and t[i] - t[i - 1] > 1.5 * step
        if start is not None and (not f or gap):
            spans.append((start - half, t[i - 1] + half))
            start = None
        if f and start is None:
            start = t[i]
    if start is not None:
        spans.append((start - half, t[-1] + half))
    return spans


def _with_gaps(t, y):
    """Insert NaN where the time step exceeds 1.5 median steps, so lines break at gaps."""
    if len(t) < 3:
        return t, y
    step = np.median(np.diff(t))
    cut = np.nonzero(np.diff(t) > 1.5 * step)[0] + 1
    return np.insert(t.astype(float), cut, np.nan), np.insert(y.astype(float), cut, np.nan)


def plot_lightcurve(lc, path=None, title: str | None = None):
    """Plot apparent magnitude versus time, one panel per site, with flags.

    Measured magnitudes with 1σ error bars; the noise-free truth (simulated data) as a line;
    epochs with the object (partly) in the Earth's shadow shaded grey (their magnitudes were
    computed as if sunlit when the file says ``ignore_eclipse``); object elevation on a
    secondary axis. Magnitude axes are inverted (brighter up). Writes a PNG atomically when
    ``path`` is given; returns the figure.
    """
    sites = list(range(len(lc.site_names)))
    fig, axes = plt.subplots(len(sites), 1, figsize=(9, 3.2 * len(sites)), sharex=True, squeeze=False)
    for k, ax in zip(sites, axes[:, 0]):
        m = lc.site == k
        if not np.any(m):
            ax.text(0.5, 0.5, "no measurement", transform=ax.transAxes, ha="center")
        ax.errorbar(lc.t[m], lc.mag[m], yerr=lc.mag_sigma[m], fmt=".", ms=3, lw=0.6, color="C0",
                    label="measured (1σ)")
        if lc.truth_mag is not None:
            ax.plot(*_with_gaps(lc.t[m], lc.truth_mag[m]), "-", lw=0.8, color="C1", label="noise-free truth")
        if lc.lit_fraction is not None and np.any(m & (lc.lit_fraction < 1)):
            for t0, t1 in _spans(lc.t[m], lc.lit_fraction[m] < 1):
                ax.axvspan(t0, t1, color="0.88", lw=0, zorder=0)
            label = "object in Earth's shadow"
            if int(lc.attrs.get("ignore_eclipse", 0)):
                label += " (computed as if sunlit)"
            ax.plot([], [], "s", color="0.88", label=label)
        ax.invert_yaxis()
        ax.set_ylabel("apparent magnitude")
        ax.set_title(f"site {lc.site_names[k]}", fontsize=9, loc="left")
        if lc.elevation_rad is not None and np.any(m):
            ax2 = ax.twinx()
            ax2.plot(*_with_gaps(lc.t[m], np.degrees(lc.elevation_rad[m])), ":", color="0.5", lw=0.8)
            ax2.set_ylabel("elevation (deg)", color="0.5")
        ax.legend(fontsize=7, loc="best")
    axes[-1, 0].set_xlabel(f"time since {lc.epoch_utc} (s)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if path is not None:
        path = Path(path)
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=110, format="png")
    return fig
