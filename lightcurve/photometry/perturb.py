"""Perturbed reflection parameters of a shape: the truth of reflection-parameter studies.

Bernard (2021) §10.1: the true facet parameters differ from the nominal shape model by a
relative Gaussian error of 1σ ``frac`` (10 % in the thesis), drawn independently per parameter.
Used by the simulation (``[reflection]`` in a scenario) and by the synthetic cases of the
reflection-parameter fit.
"""

from __future__ import annotations

import numpy as np

from ..core.photometry import COOK_TORRANCE

__all__ = ["REFLECTION_KINDS", "perturb_reflection"]

REFLECTION_KINDS = ("xi", "a", "m", "A")
"""Cook–Torrance parameters of a facet: ξ, a (= F0), m (Beckmann slope), A (area, m²)."""
_LOGIT = ("xi", "a")


def perturb_reflection(shape, rng, frac=0.1, kinds=REFLECTION_KINDS, facets=None):
    """Perturbed copy of ``shape`` (Bernard §10.1): each Cook–Torrance parameter p of the chosen
    facets ← p + N(0, (frac·p)²), redrawn (up to 100 times) until in range (ξ, a in (0,1), m, A
    > 0). Returns (shape_copy, dict kind -> (F,) new values; NaN for ξ, a, m of facets whose
    BRDF is not Cook–Torrance)."""
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    ct = (shape.model_ids == COOK_TORRANCE) & (shape.areas_m2 > 0)
    sel = np.zeros(shape.n_facets, bool)
    sel[np.flatnonzero(ct) if facets is None else np.asarray(facets, int)] = True
    sel &= ct
    cols = {"xi": 0, "a": 1, "m": 2}
    new = {k: shape.params[:, cols[k]].copy() for k in cols}
    new["A"] = shape.areas_m2.copy()
    for k in kinds:
        for i in np.flatnonzero(sel):
            p0 = new[k][i]
            for _ in range(100):
                p = p0 + frac * p0 * rng.standard_normal()
                if p > 0 and (p < 1 or k not in _LOGIT):
                    break
            else:
                p = p0
            new[k][i] = p
    ctx = ~np.isnan(shape.param_table.get("xi", np.full(shape.n_facets, np.nan)))
    kw = {k: np.where(ctx, new[k], np.nan) for k in ("xi", "a", "m")}
    out = shape.copy_with(areas_m2=new["A"], check=False, **kw) if np.any(ctx) \
        else shape.copy_with(areas_m2=new["A"], check=False)
    new.update(kw)  # NaN for facets without Cook–Torrance parameters
    return out, new
