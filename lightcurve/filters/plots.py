"""Figures of a filter run (matplotlib, Agg): errors with ±3σ, RSS error, residuals, PF clouds.

* :func:`plot_estimate` — one PNG: per-axis attitude error (deg) with ±3σ bounds, per-axis
  rate error (deg/s) with ±3σ, RSS attitude error, and the normalised innovations
  ``ν/√S`` with ±3 bounds (Bernard fig. 9.4-style). Without truth only the 3σ bounds and the
  innovations are drawn.
* :func:`plot_particle_clouds` — particle error rotation vectors (deg, body axes) at the
  stored epochs, projected on the three coordinate planes (Bernard fig. 9.6-style).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.atomic import atomic_path

__all__ = ["plot_estimate", "plot_particle_clouds"]


def _fig():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_estimate(est, path, title=None):
    """Write the error / 3σ / residual figure of an :class:`Estimate` to ``path`` (PNG)."""
    plt = _fig()
    t = est.t - est.t[0]
    fig, ax = plt.subplots(4, 3, figsize=(13, 11), sharex=True)
    names = ("x", "y", "z")
    s3a = 3 * est.att_sigma_deg
    s3w = np.degrees(3 * est.omega_sigma_rad_s)
    for j in range(3):
        a = ax[0, j]
        a.fill_between(t, -s3a[:, j], s3a[:, j], color="0.85", label="±3σ")
        if est.att_error_deg is not None:
            a.plot(t, est.att_error_deg[:, j], "C0", lw=1, label="error")
        a.set_ylabel(f"δθ_{names[j]} [deg]")
        a = ax[1, j]
        a.fill_between(t, -s3w[:, j], s3w[:, j], color="0.85")
        if est.omega_error_rad_s is not None:
            a.plot(t, np.degrees(est.omega_error_rad_s[:, j]), "C1", lw=1)
        a.set_ylabel(f"δω_{names[j]} [deg/s]")
    ax[0, 0].legend(loc="upper right", fontsize=8)
    a = ax[2, 0]
    if est.att_error_deg is not None:
        a.semilogy(t, np.maximum(np.linalg.norm(est.att_error_deg, axis=1), 1e-6), "C0")
    a.semilogy(t, np.linalg.norm(s3a, axis=1) / 3, "k--", lw=0.8, label="RSS 1σ")
    a.set_ylabel("RSS attitude error [deg]")
    a.legend(fontsize=8)
    a = ax[2, 1]
    if est.omega_error_rad_s is not None:
        a.semilogy(t, np.maximum(np.degrees(np.linalg.norm(est.omega_error_rad_s, axis=1)), 1e-9),
                   "C1")
    a.set_ylabel("RSS rate error [deg/s]")
    a = ax[2, 2]
    if est.nees is not None:
        a.semilogy(t, est.nees, "C2", lw=1)
        a.axhline(6.0, color="k", lw=0.8, ls="--")
    a.set_ylabel("NEES (6 dof)")
    a = ax[3, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        z = est.innovations / np.sqrt(est.innovation_var)
    a.plot(t, z, ".", ms=3)
    a.axhline(3, color="r", lw=0.8)
    a.axhline(-3, color="r", lw=0.8)
    a.set_ylabel("ν/√S")
    a = ax[3, 1]
    a.plot(t, est.innovations, ".", ms=3)
    a.set_ylabel("residual [mag]")
    a = ax[3, 2]
    if np.any(np.isfinite(est.n_eff)):
        a.plot(t, est.n_eff, "C4")
        a.set_ylabel("N_eff")
    else:
        a.axis("off")
    for a in ax[3]:
        a.set_xlabel("t − t₀ [s]")
    fig.suptitle(title or f"{est.method}: final RSS error "
                 + (f"{np.linalg.norm(est.att_error_deg[-1]):.3f} deg"
                    if est.att_error_deg is not None else "(no truth)"))
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
    return path


def plot_particle_clouds(est, path, title=None):
    """Write the particle-cloud figure (error rotation vectors, deg) of a BPF estimate."""
    if not est.clouds:
        raise ValueError("the estimate has no particle clouds (run the BPF with keep_clouds=… "
                         "on a lightcurve with truth)")
    plt = _fig()
    ks = sorted(est.clouds)
    fig, ax = plt.subplots(len(ks), 3, figsize=(11, 3.4 * len(ks)), squeeze=False)
    pairs = ((0, 1), (0, 2), (1, 2))
    lab = ("δθx", "δθy", "δθz")
    for r, k in enumerate(ks):
        c = est.clouds[k]
        for j, (a_, b_) in enumerate(pairs):
            a = ax[r, j]
            a.plot(c[:, a_], c[:, b_], ".", ms=1, alpha=0.4)
            a.plot([0], [0], "r+", ms=10)
            a.set_xlabel(f"{lab[a_]} [deg]")
            a.set_ylabel(f"{lab[b_]} [deg]")
            a.set_title(f"t = {est.t[k] - est.t[0]:.0f} s", fontsize=9)
    fig.suptitle(title or "particle error clouds (truth at the red cross)")
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=80, format="png")
    plt.close(fig)
    return path
