"""Refitting the object's own surface parameters, as one candidate among the effects.

The candidate ``surface`` frees the reflection parameters of the shape's BRDFs (Phong ``Kd``,
``Ks``, ``n``; Cook–Torrance ``xi``, ``a``, ``m`` …, per facet) that the user did not
already free, and competes with the physics effects on held-out gain (:mod:`.selection`); it
is never switched on silently.

Degenerate sets are fitted as their identifiable combination. Facet areas are never free, so
an amplitude parameter (Lambert albedo, Phong ``Kd``/``Ks``) is the identifiable product with
the area (``Kd·A``, m²; the report shows it so). Within a BRDF, parameters whose effect on
the data is (nearly) a combination of others' — a facet seen only in diffuse geometry, whose
Cook–Torrance ``xi`` and ``a`` act only through ``xi·a``; every amplitude when a free zero
point already absorbs the overall scale — are found by a column-pivoted QR decomposition of
the Jacobian of the standardised residuals at the scenario's values, each column scaled by
its parameter's bound interval (Golub & Van Loan, *Matrix Computations*, 4th ed., §5.4.2).
A parameter is kept when its pivoted diagonal |R_jj| exceeds ``RANK_TOLERANCE`` × |R_00|
(independent of the others) and moving it over its whole interval changes χ² by more than
``MIN_CHI2_SPAN`` (the data see it); the others stay at the scenario's values, and the
report names them with the kept parameter they are degenerate with.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import qr

__all__ = ["surface_free_params", "identifiable_subset", "RANK_TOLERANCE", "MIN_CHI2_SPAN",
           "AMPLITUDE_PARAMS", "SURFACE_DESCRIPTION"]

RANK_TOLERANCE = 1e-2
MIN_CHI2_SPAN = 4.0

#: BRDF parameters that scale the reflected light linearly (identifiable only times the area)
AMPLITUDE_PARAMS = {"lambert": ("albedo",), "phong": ("Kd", "Ks")}

SURFACE_DESCRIPTION = ("Surface refit: the object's own reflection parameters (how diffuse, "
                       "how shiny, how bright each surface is) differ from the model's values.")


def surface_free_params(problem) -> list:
    """FreeParams of every BRDF parameter of the shape that is not already free."""
    from .problem import _free_params

    if problem.kind != "magnitude":
        return []
    shape = problem.ctx.shape
    have = {p.name for p in problem.free}
    return [p for p in _free_params(["reflection"], shape, problem.channel_names) if p.name not in have]


def identifiable_subset(problem, theta0, candidates, terms=()):
    """Split ``candidates`` (FreeParams to add to ``problem.free``) into identifiable ones and
    degenerate ones (module docstring).

    Returns ``(kept, dropped)`` with ``dropped`` a list of ``(FreeParam, reason)``.
    """
    base = problem.with_free(list(problem.free) + list(candidates))
    x0 = np.r_[np.asarray(theta0, float), [p.x0 for p in candidates]]
    nb = len(problem.free)
    z0 = base.standardized(base.predict(x0, terms))
    cols = []
    for j, p in enumerate(candidates):
        span = p.hi - p.lo
        h = 1e-3 * span
        x = x0.copy()
        step = h if x[nb + j] + h <= p.hi else -h
        x[nb + j] += step
        z1 = base.standardized(base.predict(x, terms))
        cols.append((z1 - z0) / step * span)
    J = np.array(cols).T if cols else np.zeros((problem.n, 0))
    # baseline free columns too: a candidate degenerate with an already-free parameter
    bcols = []
    for j, p in enumerate(problem.free):
        span = p.hi - p.lo
        h = 1e-3 * span
        x = x0.copy()
        step = h if x[j] + h <= p.hi else -h
        x[j] += step
        z1 = base.standardized(base.predict(x, terms))
        bcols.append((z1 - z0) / step * span)
    B = np.array(bcols).T if bcols else np.zeros((problem.n, 0))
    kept, dropped = [], []
    seen = np.sqrt(np.sum(J * J, axis=0)) if J.size else np.zeros(0)
    usable = [j for j in range(len(candidates)) if seen[j] ** 2 > MIN_CHI2_SPAN]
    for j in range(len(candidates)):
        if j not in usable:
            dropped.append((candidates[j], "the data do not see it (χ² changes by < "
                            f"{MIN_CHI2_SPAN:g} over its whole range)"))
    if usable:
        A = np.hstack([B, J[:, usable]])
        _, R, piv = qr(A, mode="economic", pivoting=True)
        d = np.abs(np.diag(R))
        ref = d[0] if d.size and d[0] > 0 else 1.0
        ok_cols = {int(piv[i]) for i in range(d.size) if d[i] > RANK_TOLERANCE * ref}
        names_all = [p.name for p in problem.free] + [candidates[j].name for j in usable]
        for c, j in enumerate(usable):
            col = B.shape[1] + c
            if col in ok_cols:
                kept.append(candidates[j])
            else:
                others = [i for i in ok_cols if i != col]
                partner = ""
                if others:
                    sol, *_ = np.linalg.lstsq(A[:, others], A[:, col], rcond=None)
                    partner = names_all[others[int(np.argmax(np.abs(sol)))]]
                dropped.append((candidates[j], "degenerate with " + (partner or "the other parameters")
                                + " (only their combination is identifiable); held at the model's value"))
    return kept, dropped
