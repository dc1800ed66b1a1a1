"""Monte Carlo filter-tuning helpers built on the consistency statistics (O'Keefe 2015,
§5 eq. 5.1-5.11; Bar-Shalom, Li & Kirubarajan 2001 §5.4.2).

* :func:`consistency_summary` — averaged NEES, NMEE and (optionally) averaged NIS of a set of
  Monte Carlo runs against their two-sided χ² / normal acceptance bands, as fractions of
  epochs inside the bands;
* :func:`nis_ratio` — the ratio ``mean(NIS)/dof`` of a pooled set of NIS values with its
  ``prob`` confidence interval (``Σ NIS ~ χ²_{n·dof}``): > 1 means the filter is
  over-confident (increase R or Q), < 1 pessimistic;
* :func:`tune_parameter` — pick, from a grid, the value of one tuning parameter whose pooled
  NIS (or NEES) ratio is closest to 1 in log scale.

Array conventions follow :mod:`lightcurve.estimation.consistency` (runs on axis 0).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from .consistency import chi2_consistency, nees, nis, nmee, nmee_interval

__all__ = ["consistency_summary", "nis_ratio", "tune_parameter"]


def consistency_summary(errs, P, nus=None, S=None, prob=0.95) -> dict:
    """Consistency of N Monte Carlo runs.

    errs (N, T, n) estimation errors x_true − x̂, P (N, T, n, n); optional innovations
    nus (N, T, m) with covariances S (N, T, m, m).  Returns a dict with ``nees`` (T,) averaged
    NEES, ``nees_band`` (lo, hi), ``nees_inside`` (fraction of epochs inside), ``nmee`` (T, n),
    ``nmee_band``, ``nmee_inside`` (fraction over epochs and components), and, with
    innovations, ``nis`` / ``nis_band`` / ``nis_inside``.
    """
    e = np.asarray(errs, dtype=float)
    if e.ndim != 3:
        raise ValueError(f"errs must have shape (N, T, n), got {e.shape}")
    N, _, n = e.shape
    ne = np.mean(nees(e, P), axis=0)
    c = chi2_consistency(ne, n, N, prob)
    mu = nmee(e, P)
    lo, hi = nmee_interval(N, prob)
    out = {"nees": ne, "nees_band": (c.lo, c.hi), "nees_inside": c.fraction_inside,
           "nmee": mu, "nmee_band": (lo, hi),
           "nmee_inside": float(np.mean((mu >= lo) & (mu <= hi)))}
    if nus is not None:
        v = np.asarray(nus, dtype=float)
        ni = np.mean(nis(v, S), axis=0)
        cn = chi2_consistency(ni, v.shape[-1], v.shape[0], prob)
        out.update({"nis": ni, "nis_band": (cn.lo, cn.hi), "nis_inside": cn.fraction_inside})
    return out


def nis_ratio(values, dof=1, prob=0.95):
    """``(ratio, lo, hi)``: mean of the finite NIS ``values`` divided by ``dof``, and the
    two-sided ``prob`` interval of that ratio for a consistent filter (independent samples:
    ``Σ NIS ~ χ²_{K·dof}``)."""
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise ValueError("no finite NIS values")
    k = v.size * int(dof)
    a = 0.5 * (1.0 - prob)
    return (float(v.mean() / dof), float(stats.chi2.ppf(a, k) / k),
            float(stats.chi2.ppf(1 - a, k) / k))


def tune_parameter(run, grid, dof=1):
    """Grid search of one tuning parameter for consistency.

    ``run(value)`` returns an array of NIS (or NEES) values pooled over Monte Carlo runs for
    that parameter value; ``dof`` their degrees of freedom.  Returns ``(best_value, table)``
    with ``table`` a list of ``(value, ratio)``; the best value minimises |log(ratio)|.
    """
    table = []
    for g in grid:
        r, _, _ = nis_ratio(run(g), dof)
        table.append((g, r))
    if not table:
        raise ValueError("empty grid")
    best = min(table, key=lambda t: abs(np.log(max(t[1], 1e-300))))
    return best[0], table
