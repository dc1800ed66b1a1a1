"""Residual analysis: standardised residuals, whiteness tests, χ² band, systematic segments.

* :func:`ljung_box` — Ljung & Box (1978, Biometrika 65, 297): Q = n(n+2) Σ_{k=1..h} ρ̂_k²/(n−k)
  of the residuals in time order, χ²(h) under white noise.
* :func:`runs_test` — Wald & Wolfowitz (1940) runs test of the signs about zero: the number
  of runs R has mean 2 n₊n₋/n + 1 and variance 2n₊n₋(2n₊n₋ − n)/(n²(n − 1)); two-sided
  normal p-value.
* :func:`chi2_band` — the two-sided (1 − α) interval of χ²/dof for ``dof`` degrees of freedom
  (from :func:`scipy.stats.chi2.ppf`).
* :func:`find_segments` — where the standardised residuals z are not N(0, 1): per site,
  per time block (contiguous runs split at gaps, at most ``block`` measurements), and per
  geometry regime (low elevation < 20°, near shadow: within 500 km of the shadow
  cylinder or in penumbra, high solar phase angle > 120°). A segment is *systematic* when
  its χ² = Σz² (or its mean, |Σz|/√n) is improbable under N(0,1): p < ``alpha`` divided by
  the number of segments tested (Bonferroni), so the family-wise false-alarm rate of a
  white-noise recording is ≤ ``alpha`` (0.01 by default).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

__all__ = ["ljung_box", "runs_test", "chi2_band", "whiteness", "find_segments",
           "consistency", "LOW_ELEVATION_DEG", "HIGH_PHASE_DEG", "NEAR_SHADOW_M"]

LOW_ELEVATION_DEG = 20.0
HIGH_PHASE_DEG = 120.0
NEAR_SHADOW_M = 500e3


def ljung_box(z, lags: int | None = None) -> dict:
    """Ljung–Box portmanteau test of residuals ``z`` (time order). Returns Q, lags, p."""
    z = np.asarray(z, float)
    n = z.size
    if lags is None:
        lags = int(min(20, max(1, n // 5)))
    lags = int(min(lags, n - 2)) if n > 3 else 0
    if lags < 1:
        return {"q": 0.0, "lags": 0, "p_value": 1.0}
    d = z - z.mean()
    den = float(d @ d)
    if den <= 0:
        return {"q": 0.0, "lags": lags, "p_value": 1.0}
    rho = np.array([float(d[k:] @ d[:-k]) / den for k in range(1, lags + 1)])
    q = n * (n + 2) * float(np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    return {"q": q, "lags": lags, "p_value": float(stats.chi2.sf(q, lags))}


def runs_test(z) -> dict:
    """Wald–Wolfowitz runs test of the signs of ``z`` about zero (two-sided normal p)."""
    s = np.asarray(z, float)
    s = s[s != 0] > 0
    n = s.size
    n1 = int(s.sum())
    n2 = n - n1
    if n < 3 or n1 == 0 or n2 == 0:
        return {"runs": int(n > 0), "expected": float("nan"), "p_value": 1.0 if n < 3 else 0.0}
    runs = 1 + int(np.sum(s[1:] != s[:-1]))
    mu = 2.0 * n1 * n2 / n + 1.0
    var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n**2 * (n - 1.0))
    zz = (runs - mu) / np.sqrt(var) if var > 0 else 0.0
    return {"runs": runs, "expected": mu, "p_value": float(2.0 * stats.norm.sf(abs(zz)))}


def chi2_band(dof: int, alpha: float = 0.002) -> tuple[float, float]:
    """Two-sided (1 − alpha) band of χ²/dof for ``dof`` degrees of freedom."""
    dof = max(int(dof), 1)
    return (float(stats.chi2.ppf(alpha / 2, dof) / dof), float(stats.chi2.isf(alpha / 2, dof) / dof))


def whiteness(z, t, alpha: float = 0.001) -> dict:
    """Ljung–Box and runs tests of ``z`` in time order; ``white`` when both p ≥ alpha."""
    order = np.argsort(np.asarray(t, float), kind="stable")
    zo = np.asarray(z, float)[order]
    lb = ljung_box(zo)
    rt = runs_test(zo)
    return {"ljung_box": lb, "runs": rt, "alpha": alpha,
            "white": bool(lb["p_value"] >= alpha and rt["p_value"] >= alpha)}


def consistency(z, t, n_params: int, *, alpha_chi2: float = 0.002, alpha_white: float = 0.001) -> dict:
    """Is the model consistent with the stated noise? χ²/dof against its band, whiteness.

    ``consistent`` when χ²/dof is not above the upper edge of its two-sided (1 − alpha_chi2)
    band and either the residuals are white (Ljung–Box and runs tests at alpha_white) or
    χ²/dof ≤ 1. A χ²/dof at or below 1 — even below the band, a fit tighter than the stated
    noise (the σ are overstated) — is consistency, never a mismatch: whatever structure the
    residuals have is smaller than the noise the recording claims. ``tighter_than_noise``
    flags χ²/dof below the band. False-alarm rate for residuals that really are white
    N(0,1): ≤ alpha_chi2/2 + 2·alpha_white (0.3 % with the defaults).
    """
    z = np.asarray(z, float)
    dof = max(z.size - int(n_params), 1)
    c2 = float(z @ z)
    lo, hi = chi2_band(dof, alpha_chi2)
    w = whiteness(z, t, alpha_white)
    r = c2 / dof
    in_band = lo <= r <= hi
    ok = bool(r <= hi and (w["white"] or r <= 1.0))
    return {"chi2": c2, "dof": dof, "chi2_dof": r, "chi2_dof_band": [lo, hi],
            "chi2_in_band": bool(in_band), "tighter_than_noise": bool(r < lo), "whiteness": w,
            "consistent": ok}


def _segment(kind, label, m, z, t, n_tests, alpha):
    zz = z[m]
    n = int(zz.size)
    c2 = float(zz @ zz)
    p_chi = float(stats.chi2.sf(c2, n))
    p_mean = float(2 * stats.norm.sf(abs(zz.sum()) / np.sqrt(n)))
    p = min(p_chi, p_mean)
    return {"kind": kind, "label": label, "n": n, "t_start_s": float(t[m].min()),
            "t_end_s": float(t[m].max()), "mean_z": float(zz.mean()), "chi2_per_n": c2 / n,
            "p_value": p, "systematic": bool(p < alpha / max(n_tests, 1))}


def _time_label(problem, t0, t1) -> str:
    """'YYYY-MM-DD hh:mm:ss–hh:mm:ss UTC' when the problem has an epoch, else seconds."""
    epoch = getattr(problem.ctx, "epoch_utc", None)
    if not epoch:
        return f"{t0:.1f}-{t1:.1f} s"
    from datetime import timedelta

    from ..geometry.time import parse_epoch

    e = parse_epoch(epoch)
    a, b = e + timedelta(seconds=float(t0)), e + timedelta(seconds=float(t1))
    tail = b.strftime("%H:%M:%S") if a.date() == b.date() else b.strftime("%Y-%m-%d %H:%M:%S")
    return f"{a.strftime('%Y-%m-%d %H:%M:%S')}–{tail} UTC"


def find_segments(problem, z, *, alpha: float = 0.01, block: int = 30, min_n: int = 5) -> list[dict]:
    """Locate systematic residuals (module docstring); sorted by p-value, systematic first.

    ``problem`` supplies ``t``, ``site``, ``site_names``, ``epoch_index`` and the per-epoch
    geometry (``elevation_rad``, ``phase_rad``, ``shadow_margin``, NaN/None when unknown).
    When the residuals as a whole are wider than the noise (χ²/n = s² > 1), every segment
    would fail a test against N(0, 1); the segments are then tested against N(0, s²) —
    "worse than the rest of the recording" — and ``scale`` records s.
    """
    z = np.asarray(z, float)
    s2 = float(z @ z) / max(z.size, 1)
    scale = math.sqrt(s2) if s2 > 1.0 else 1.0
    z = z / scale
    t = np.asarray(problem.t, float)
    cands = []
    site_word = "sensor" if problem.kind == "css" else "site"
    for k, name in enumerate(problem.site_names):
        m = problem.site == k
        if m.sum() >= min_n:
            cands.append((site_word, name, m))
    # time blocks: split at gaps > 5× the median spacing, then into chunks of ≤ block
    order = np.argsort(t, kind="stable")
    tu = np.unique(t)
    gap = 5 * np.median(np.diff(tu)) if tu.size > 2 else np.inf
    ts = t[order]
    cuts = np.flatnonzero(np.diff(ts) > gap) + 1
    groups = np.split(order, cuts)
    for g in groups:
        nchunk = max(1, int(np.ceil(g.size / block)))
        for c in np.array_split(g, nchunk):
            if c.size >= min_n:
                m = np.zeros(z.size, bool)
                m[c] = True
                cands.append(("time", _time_label(problem, t[c].min(), t[c].max()), m))
    ei = problem.epoch_index
    if problem.elevation_rad is not None:
        el = np.degrees(np.asarray(problem.elevation_rad, float))[ei]
        m = el < LOW_ELEVATION_DEG
        if min_n <= m.sum() < z.size:
            cands.append(("geometry", f"low elevation (< {LOW_ELEVATION_DEG:.0f} deg)", m))
    if problem.shadow_margin is not None:
        sm = np.asarray(problem.shadow_margin, float)[ei]
        m = sm < NEAR_SHADOW_M
        if min_n <= m.sum() < z.size:
            cands.append(("geometry", f"near shadow (< {NEAR_SHADOW_M / 1e3:.0f} km from the shadow "
                          "boundary)", m))
    if problem.phase_rad is not None:
        ph = np.degrees(np.asarray(problem.phase_rad, float))[ei]
        m = ph > HIGH_PHASE_DEG
        if min_n <= m.sum() < z.size:
            cands.append(("geometry", f"high phase (> {HIGH_PHASE_DEG:.0f} deg)", m))
    segs = [_segment(kind, label, m, z, t, len(cands), alpha) for kind, label, m in cands]
    for sg in segs:
        sg["scale"] = scale
    segs.sort(key=lambda s: (not s["systematic"], s["p_value"]))
    return segs
