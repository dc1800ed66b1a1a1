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


def _with_gaps(t, y, min_gap_s: float = 0.0):
    """Insert NaN where the time step exceeds 1.5 median steps (and ``min_gap_s``), so lines
    break at gaps."""
    if len(t) < 3:
        return t, y
    step = np.median(np.diff(t))
    cut = np.nonzero(np.diff(t) > max(1.5 * step, min_gap_s))[0] + 1
    return np.insert(t.astype(float), cut, np.nan), np.insert(y.astype(float), cut, np.nan)


def plot_lightcurve(lc, path=None, title: str | None = None):
    """Plot apparent magnitude versus UTC, one panel per site, with flags.

    Measured magnitudes with 1σ error bars; the noise-free truth (simulated data) as a line;
    epochs with the object (partly) in the Earth's shadow shaded grey (their magnitudes were
    computed as if sunlit when the file says ``ignore_eclipse``); object elevation on a
    secondary axis. Magnitude axes are inverted (brighter up); time in UTC
    (:mod:`lightcurve.report.style`). The title gives the number of measurements, the span
    and the magnitude range. Writes a PNG atomically when ``path`` is given; returns the figure.
    """
    from .style import DPI, figsize, utc_axis, utc_times

    sites = [k for k in range(len(lc.site_names)) if np.any(lc.site == k)] or [0]
    fig, axes = plt.subplots(len(sites), 1, figsize=figsize(10, 3.0 * len(sites) + 0.8),
                             sharex=True, squeeze=False, dpi=DPI, layout="constrained")
    try:
        x = utc_times(lc.epoch_utc, lc.t)
        is_utc = True
    except Exception:  # noqa: BLE001  an unusable epoch: seconds
        x, is_utc = np.asarray(lc.t, float), False
    for k, ax in zip(sites, axes[:, 0]):
        m = lc.site == k
        ax.errorbar(x[m], lc.mag[m], yerr=lc.mag_sigma[m], fmt=".", ms=3, lw=0.6, color="C0",
                    label="measured (1σ)")
        if lc.truth_mag is not None:
            xt, yt = _with_gaps(lc.t[m], lc.truth_mag[m])
            xt = utc_times(lc.epoch_utc, xt) if is_utc else xt
            ax.plot(xt, yt, "-", lw=0.8, color="C1", label="noise-free truth")
        if lc.lit_fraction is not None and np.any(m & (lc.lit_fraction < 1)):
            for t0, t1 in _spans(lc.t[m], lc.lit_fraction[m] < 1):
                if is_utc:
                    t0, t1 = utc_times(lc.epoch_utc, [t0, t1])
                ax.axvspan(t0, t1, color="0.88", lw=0, zorder=0)
            label = "object in Earth's shadow"
            if int(lc.attrs.get("ignore_eclipse", 0)):
                label += " (computed as if sunlit)"
            ax.plot([], [], "s", color="0.88", label=label)
        ax.invert_yaxis()
        ax.set_ylabel("apparent magnitude")
        ax.set_title(f"site {lc.site_names[k]}", fontsize=9, loc="left")
        handles, labels = ax.get_legend_handles_labels()
        if lc.elevation_rad is not None and np.any(m):
            ax2 = ax.twinx()
            # the elevation is smooth through epochs without a magnitude (no lit facet facing
            # the observer, dropped samples): the line breaks only between passes
            xe, ye = _with_gaps(lc.t[m], np.degrees(lc.elevation_rad[m]), min_gap_s=600.0)
            xe = utc_times(lc.epoch_utc, xe) if is_utc else xe
            ln, = ax2.plot(xe, ye, ":", color="0.5", lw=0.9, label="elevation (right axis)")
            ax2.set_ylabel("elevation (deg)", color="0.5")
            handles.append(ln)
            labels.append(ln.get_label())
        ax.legend(handles, labels, fontsize=7, loc="best")
        ax.grid(True, alpha=0.3)
    if is_utc:
        utc_axis(axes[-1, 0], label="UTC")
    else:
        axes[-1, 0].set_xlabel(f"time since {lc.epoch_utc} (s)")
    fin = np.isfinite(lc.mag)
    span = ""
    if is_utc and len(lc):
        a, b = str(x[0])[:19].replace("T", " "), str(x[-1])[11:19]
        span = f", {a}–{b} UTC"
    rng = (f", {np.nanmin(lc.mag):.1f} to {np.nanmax(lc.mag):.1f} mag" if np.any(fin) else "")
    head = f"{int(fin.sum())} magnitudes from {len(sites)} site{'s' if len(sites) > 1 else ''}{span}{rng}"
    fig.suptitle(f"{title}: {head}" if title else head, fontsize=10)
    if path is not None:
        path = Path(path)
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=DPI, format="png")
    return fig
