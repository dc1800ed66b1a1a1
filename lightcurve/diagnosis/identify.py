"""Are an effect's fitted parameters identified by the data?

An effect is *named* only when every parameter the data constrain is identified; otherwise it
"fits, but is unidentifiable with these data". For each continuous parameter of the term
(the Gaussian (Laplace) posterior of the least-squares fit: value x, 1σ from the scaled
(JᵀJ)⁺ covariance of :func:`~.baseline.fit_terms`):

1. **not at a bound**: x is farther than ``AT_BOUND_FRACTION`` of the bound interval from
   both fit bounds (the fit bounds lie a quarter of the prior's span outside its support,
   :func:`~.baseline.prior_bounds`, so a value at a bound is outside anything the prior calls
   realistic, or the optimiser ran into it);
2. **constrained**: the posterior sd is below ``MAX_POSTERIOR_TO_PRIOR_SD`` times the prior's
   sd (uniform: span/√12; log-uniform: the same in ln x, compared with sd/x; signed uniform:
   √((a² + ab + b²)/3); normal: its sd) — the data, not the prior, set the value;
3. **detected** (amplitudes, i.e. parameters with a ``null`` value at which the effect
   vanishes): |x − null| > ``DETECTION_SIGMAS`` sd; for a parameter with one value per site,
   camera or sensor the vector as a whole — the Wald statistic dᵀΣ⁻¹d of d = x − null over
   its constrained components exceeds the χ²(k) quantile of the same two-sided level (95.45 %)
   — since a misalignment or scale factor that is zero on some sensors is still detected on
   the others;
4. **not degenerate**: |correlation| with every other fitted parameter (baseline and other
   effects) below ``MAX_CORRELATION`` (0.999).

Parameters the data do not touch at all (zero Jacobian column: a per-site value of a site
without measurements, a sensor that never sees the Sun) cannot change any prediction; they
are listed as "no data" and do not block naming. A component of a per-site/camera/sensor
parameter that fails criterion 2 alone (a sensor that sees the Sun only briefly, or along a
path that hardly moves its normal in one direction) is held at its reference value by the
diagnosis and the effect refitted (:func:`weak_components`); the effect is named when the
rest is identified and still detected. Integer and grid parameters (a CSS sensor
index, a fault time) are identified by their profile likelihood over the enumerated values:
the best value must beat every other sensor by Δχ² > ``GRID_DELTA_CHI2_INTEGER``; a step
time is identified when its profile rises by Δχ² > ``GRID_DELTA_CHI2_STEP`` somewhere on the
grid, and reported as the interval of grid times within that Δχ² of the best (a fault of a
sensor that did not see the Sun for a while can only be dated to that while).

The limits are chosen once here (not tuned per case): 0.001 of the interval is a value the
optimiser's bound handling leaves only when pinned; a posterior at most half the prior's
width means the data carry at least 4× the prior's information; 2σ is the conventional
detection level. A correlation inflates the marginal sd, which criterion 2 already judges
(two parameters can both be well determined and correlated at 0.99, e.g. a glint's azimuth
and elevation seen along one arc); |ρ| ≥ 0.999 flags the near-exact degeneracies where only a
combination is determined and the linearised covariance itself cannot be trusted (an
amplitude traded against a zero point, area against exponent of an unresolved lobe).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from .baseline import prior_support

__all__ = ["identify_term", "identify_free", "weak_components", "AT_BOUND_FRACTION", "MAX_POSTERIOR_TO_PRIOR_SD",
           "DETECTION_SIGMAS", "MAX_CORRELATION", "GRID_DELTA_CHI2_INTEGER",
           "GRID_DELTA_CHI2_STEP", "prior_sd"]

AT_BOUND_FRACTION = 1e-3
MAX_POSTERIOR_TO_PRIOR_SD = 0.5
DETECTION_SIGMAS = 2.0
MAX_CORRELATION = 0.999
GRID_DELTA_CHI2_INTEGER = 10.0
GRID_DELTA_CHI2_STEP = 4.0


def prior_sd(spec) -> tuple[float, bool]:
    """(prior sd, in_log) of a ParamSpec's prior (module docstring, criterion 2)."""
    pr = spec.prior
    if pr.kind == "uniform":
        return (pr.b - pr.a) / math.sqrt(12.0), False
    if pr.kind == "log_uniform":
        return math.log(pr.b / pr.a) / math.sqrt(12.0), True
    if pr.kind == "signed_uniform":
        return math.sqrt((pr.a * pr.a + pr.a * pr.b + pr.b * pr.b) / 3.0), False
    if pr.kind == "normal":
        return float(pr.b), False
    lo, hi = prior_support(spec)
    return (hi - lo) / math.sqrt(12.0), False


def _corr(fit):
    cov = fit.cov
    if cov is None:
        return None
    d = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        c = cov / np.outer(d, d)
    return np.where(np.isfinite(c), c, 0.0)


def _check_entry(fit, i, corr, prior_scale, in_log, null, joint=False):
    x = float(fit.x[i])
    lo, hi = float(fit.lo[i]), float(fit.hi[i])
    sd = float(fit.sd[i]) if fit.sd is not None else float("nan")
    rec = {"value": x, "sd": sd if math.isfinite(sd) else None}
    if fit.dead is not None and fit.dead[i]:
        rec.update(status="no data", ok=True)
        return rec
    reasons = []
    span = hi - lo
    if math.isfinite(span) and (x - lo <= AT_BOUND_FRACTION * span or hi - x <= AT_BOUND_FRACTION * span):
        reasons.append("at a bound of its range")
    if not math.isfinite(sd):
        reasons.append("uncertainty unknown")
    else:
        post = sd / abs(x) if in_log and x != 0 else sd
        rec["posterior_to_prior_sd"] = post / prior_scale if prior_scale > 0 else None
        if post > MAX_POSTERIOR_TO_PRIOR_SD * prior_scale:
            reasons.append(f"posterior sd {post / prior_scale:.2g}× the prior's")
        if null is not None and not joint and not abs(x - null) > DETECTION_SIGMAS * sd:
            reasons.append(f"within {DETECTION_SIGMAS:g} sd of {null:g} (no effect)")
    if corr is not None:
        row = np.abs(corr[i].copy())
        row[i] = 0.0
        if fit.dead is not None:
            row[fit.dead] = 0.0
        j = int(np.argmax(row)) if row.size else -1
        if j >= 0:
            rec["max_correlation"] = float(row[j])
            rec["correlated_with"] = fit.names[j] if j < len(fit.names) else str(j)
            if row[j] >= MAX_CORRELATION:
                reasons.append(f"correlation {row[j]:.3f} with {rec['correlated_with']}")
    rec["ok"] = not reasons
    rec["status"] = "identified" if not reasons else "; ".join(reasons)
    return rec


def identify_term(fit, effect_index: int, profiles=None) -> dict:
    """Identification of term ``effect_index`` of ``fit`` (module docstring).

    ``profiles``: optional ``[(grid_values_dict, chi2)]`` of the enumerated integer/grid
    parameters. Returns ``{"identified": bool, "params": {label: record}, "reasons": [...]}``
    with ``label`` = ``name`` or ``name[component]``.
    """
    eff, params = fit.terms[effect_index]
    corr = _corr(fit)
    out, reasons = {}, []
    vectors = {}
    for i, (owner, spec, comp) in enumerate(fit.owners):
        if owner != effect_index:
            continue
        psd, in_log = prior_sd(spec)
        rec = _check_entry(fit, i, corr, psd, in_log, spec.null, joint=comp is not None)
        label = fit.names[i].split(".", 1)[1] if "." in fit.names[i] else fit.names[i]
        out[label] = rec
        if not rec["ok"]:
            reasons.append(f"{label}: {rec['status']}")
        if comp is not None and spec.null is not None and not (fit.dead is not None and fit.dead[i]):
            vectors.setdefault(spec.name, (spec.null, []))[1].append(i)
    for name, (null, idx) in vectors.items():
        w, k = _wald(fit, idx, null)
        need = float(stats.chi2.ppf(stats.chi2.cdf(DETECTION_SIGMAS ** 2, 1), k))
        out[f"{name} (all)"] = rec = {"value": None, "sd": None, "wald": w, "wald_limit": need,
                                      "ok": bool(w > need)}
        rec["status"] = "detected" if rec["ok"] else (
            f"consistent with {null:g} everywhere (Wald {w:.3g} ≤ {need:.3g}, no effect)")
        if not rec["ok"]:
            reasons.append(f"{name}: {rec['status']}")
    for name, why in (getattr(eff, "diagnosis_hold", {}) or {}).items():
        out[name] = {"value": _scalar(params.get(name)), "sd": None, "ok": True,
                     "status": f"held: {why}"}
    for name, comps in (getattr(eff, "hold_components", None) or {}).items():
        v = params.get(name)
        for c in sorted(comps):
            out[f"{name}[{c}]"] = {"value": float(np.asarray(v)[c]) if v is not None else None,
                                   "sd": None, "ok": True,
                                   "status": "held at its reference value (this component is "
                                             "not constrained by these data)"}
    for name in getattr(eff, "hold", ()) or ():
        if name not in out:
            out[name] = {"value": _scalar(params.get(name)), "sd": None, "ok": True,
                         "status": "held at its reference value (not identified by these data)"}
    if profiles:
        for rec in _grid_identification(eff, params, profiles):
            out[rec.pop("name")] = rec
            if not rec["ok"]:
                reasons.append(f"{list(out)[-1]}: {rec['status']}")
    return {"identified": not reasons, "params": out, "reasons": reasons}


def identify_free(fit, names) -> dict:
    """Identification of the free baseline parameters ``names`` of ``fit`` (e.g. a surface
    refit): criteria 1, 2 (against the parameter's bound interval as a uniform prior) and 4.
    """
    corr = _corr(fit)
    out, reasons = {}, []
    for i, (owner, p, _) in enumerate(fit.owners):
        if owner != -1 or p.name not in names:
            continue
        span = float(fit.hi[i] - fit.lo[i])
        rec = _check_entry(fit, i, corr, span / math.sqrt(12.0), False, None)
        out[p.name] = rec
        if not rec["ok"]:
            reasons.append(f"{p.name}: {rec['status']}")
    return {"identified": not reasons, "params": out, "reasons": reasons}


def _wald(fit, idx, null):
    """Wald statistic dᵀΣ⁻¹d of the entries ``idx`` of ``fit.x`` against ``null``, and k."""
    d = fit.x[idx] - null
    if fit.cov is None:
        return float("nan"), len(idx)
    S = fit.cov[np.ix_(idx, idx)]
    w = float(d @ np.linalg.pinv(S) @ d)
    return w, len(idx)


def _scalar(v):
    if v is None:
        return None
    a = np.asarray(v, float)
    return float(a) if a.ndim == 0 else [float(x) for x in a]


def _grid_identification(eff, params, profiles):
    """Profile-likelihood identification of integer/grid parameters (module docstring)."""
    recs = []
    names = sorted({k for g, _ in profiles for k in g})
    for name in names:
        best_v = params.get(name)
        vals = sorted({float(g[name]) for g, _ in profiles if name in g})
        if len(vals) < 2 or best_v is None:
            continue
        best_c2 = min(c for g, c in profiles if float(g.get(name, np.nan)) == float(best_v)) \
            if any(float(g.get(name, np.nan)) == float(best_v) for g, _ in profiles) else \
            min(c for _, c in profiles)
        spec = next(s for s in eff.params if s.name == name)
        if spec.integer:
            others = [c for g, c in profiles if float(g[name]) != float(best_v)]
            need = GRID_DELTA_CHI2_INTEGER
            gap = (min(others) - best_c2) if others else float("inf")
            ok = gap > need
            recs.append({"name": name, "value": float(best_v), "sd": None, "ok": ok,
                         "profile_delta_chi2": float(gap) if math.isfinite(gap) else None,
                         "status": "identified" if ok else
                         f"profile likelihood flat: Δχ² {gap:.3g} ≤ {need:g} to other values"})
            continue
        prof = {v: min(c for g, c in profiles if float(g[name]) == v) for v in vals}
        rise = max(prof.values()) - best_c2
        inside = [v for v in vals if prof[v] - best_c2 <= GRID_DELTA_CHI2_STEP]
        ok = rise > GRID_DELTA_CHI2_STEP
        recs.append({"name": name, "value": float(best_v), "sd": None, "ok": ok,
                     "interval": [float(min(inside)), float(max(inside))] if inside else None,
                     "status": (f"identified within [{min(inside):.6g}, {max(inside):.6g}]"
                                if ok else f"profile likelihood flat over the whole grid "
                                f"(Δχ² ≤ {GRID_DELTA_CHI2_STEP:g})")})
    return recs


def weak_components(fit, effect_index: int, ident: dict) -> dict:
    """{parameter name: {component indices}} of the per-site/camera/sensor components of term
    ``effect_index`` whose only failed criterion is 2 (posterior too wide); empty when any
    other entry of the term fails, or when every component of a parameter would be held."""
    bad = {k: r for k, r in ident["params"].items() if not r.get("ok", True)}
    out = {}
    comps = {}
    for i, (owner, spec, comp) in enumerate(fit.owners):
        if owner != effect_index or comp is None:
            continue
        label = fit.names[i].split(".", 1)[1] if "." in fit.names[i] else fit.names[i]
        comps.setdefault(spec.name, []).append(comp)
        r = bad.get(label)
        if r is None:
            continue
        if not str(r.get("status", "")).startswith("posterior sd"):
            return {}
        out.setdefault(spec.name, set()).add(comp)
    for k in bad:
        base = k.split("[", 1)[0]
        if base not in out and not k.endswith("(all)"):
            return {}
        if k.endswith("(all)"):
            return {}
    if any(len(v) >= len(comps.get(n, ())) for n, v in out.items()):
        return {}
    return out
