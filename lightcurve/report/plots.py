"""Matplotlib figures of lightcurves (headless; the Agg backend is selected on import)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..io.atomic import atomic_path  # noqa: E402

__all__ = ["plot_lightcurve"]


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
            ax.plot(lc.t[m], lc.truth_mag[m], "-", lw=0.8, color="C1", label="noise-free truth")
        if lc.lit_fraction is not None and np.any(m & (lc.lit_fraction < 1)):
            shadow = m & (lc.lit_fraction < 1)
            for t in lc.t[shadow]:
                ax.axvspan(t - 0.5, t + 0.5, color="0.85", lw=0)
            ax.plot([], [], "s", color="0.85", label="object in Earth's shadow")
        ax.invert_yaxis()
        ax.set_ylabel("apparent magnitude")
        ax.set_title(f"site {lc.site_names[k]}", fontsize=9, loc="left")
        if lc.elevation_rad is not None and np.any(m):
            ax2 = ax.twinx()
            ax2.plot(lc.t[m], np.degrees(lc.elevation_rad[m]), ":", color="0.5", lw=0.8)
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
