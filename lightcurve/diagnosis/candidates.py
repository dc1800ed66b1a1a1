"""Score every registered effect as an explanation of the baseline residuals, and rank them.

For each effect of the problem's kind (``magnitude`` or ``css``) that is not excluded:

1. **Signature correlation**: the effect's signature columns S (its
   :meth:`~lightcurve.physics.Effect.signature_columns` on the fitted baseline, one column
   per site for per-site effects) are regressed on the standardised residuals z with
   weights 1/σ; ``signature_r`` is the multiple correlation coefficient (0…1) and the
   regression coefficients give a linearised start for the fit (e.g. k ≈ b for extinction,
   δt ≈ b for a clock offset, T ≈ √b for exposure smearing). An effect whose signature is
   identically zero on these data (self-shadowing of a convex shape, a penumbra that never
   happens) is reported as not applicable.
2. **Fit**: its continuous parameters jointly with the free baseline parameters
   (:func:`~.baseline.fit_terms`, prior support as bounds) from several starts (typical
   values, the linearised start, draws from the prior with a fixed seed, and for an extra
   facet or glint the body-frame Sun–observer bisector at the epochs most brighter than the
   model: the normal a mirror must have to flash there). Integer parameters (a CSS sensor)
   are enumerated and step times (``t_start_s``) scanned on a grid of the data's times.
3. **In-sample evidence**: ΔBIC = n ln(χ²₀/χ²₁) − k ln n (:func:`~.baseline.bic_gain`; k =
   the effect's parameter count); the list is ordered by it. The choice between candidates
   is made on held-out data by :mod:`.selection`.
"""

from __future__ import annotations

import warnings

import numpy as np

from .baseline import (GRID_PARAMS, bic_gain, fit_terms, held_names, param_layout, prior_bounds,
                       typical_params)
from ..physics.registry import Effect
from .fast import diagnosis_effect

__all__ = ["score_candidates", "signature_matrix", "candidate_starts", "params_to_json",
           "held_values"]

#: linearised start: effect → (parameter, transform of the regression coefficient)
_LINEAR = {"extinction": ("k_mag_per_airmass", "id"), "zero_point": ("offset_mag", "id"),
           "clock_offset": ("dt_s", "id"), "exposure_smearing": ("exposure_s", "sqrt"),
           "earthshine": ("albedo_scale", "id"), "css_albedo": ("albedo_scale", "id")}


def signature_matrix(effect, problem, ctx, params=None) -> np.ndarray:
    """Signature columns per measurement (M, P) on context ``ctx`` (non-finite → 0).

    Effects with a named geometric signature use it; the others (and CSS effects) use the
    change of the model caused by the effect at ``params`` (default: typical values).
    """
    from ..physics import Effect

    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if problem.kind == "css" or params is not None or type(effect).signature is Effect.signature:
            p = typical_params(effect, ctx) if params is None else {**typical_params(effect, ctx), **params}
            d = np.asarray(effect.apply(ctx, p), float) - np.asarray(ctx.evaluate(), float)
            d = np.where(np.isfinite(d), d, 0.0)
            if problem.kind == "css":
                S = d.reshape(-1, 1)
            else:
                S = d[problem.epoch_index].reshape(-1, 1)
        else:
            S = np.asarray(effect.signature_columns(ctx), float)
            S = S[problem.epoch_index]
    return np.where(np.isfinite(S), S, 0.0)


def _regress(z, S, sigma):
    """Weighted regression of z on S/σ: coefficients b (mag-unit), multiple correlation R."""
    A = S / sigma[:, None]
    keep = np.any(A != 0, axis=0)
    b = np.zeros(S.shape[1])
    if not np.any(keep):
        return b, 0.0
    sol, *_ = np.linalg.lstsq(A[:, keep], z, rcond=None)
    b[keep] = sol
    fitted = A[:, keep] @ sol
    den = float(z @ z)
    r2 = float(fitted @ fitted) / den if den > 0 else 0.0
    return b, float(np.sqrt(min(max(r2, 0.0), 1.0)))


def _bisector_starts(problem, ctx, z, n=3):
    """Facet normals (az_deg, el_deg) bisecting Sun and observer (body axes) where the data
    are most brighter than the model (z most negative: measured magnitude smaller)."""
    from ..rotations import quat_rotate

    st = ctx.state()
    out = []
    order = np.argsort(z)[:n]
    for j in order:
        e = problem.epoch_index[j]
        h = st.s_unit[e] + st.o_unit[e]
        h = quat_rotate(st.q[e], h / np.linalg.norm(h))
        out.append({"az_deg": float(np.degrees(np.arctan2(h[1], h[0]))),
                    "el_deg": float(np.degrees(np.arcsin(np.clip(h[2], -1, 1))))})
    return out


def candidate_starts(effect, problem, ctx, z, S, b, rng) -> list[dict]:
    """Start values for fitting ``effect`` (module docstring)."""
    starts = [{}]
    if effect.name in _LINEAR:
        pname, how = _LINEAR[effect.name]
        spec = {p.name: p for p in effect.params}[pname]
        lo, hi = prior_bounds(spec)
        vals = np.sqrt(np.maximum(b, 0.0)) if how == "sqrt" else b
        vals = np.clip(vals, lo, hi)
        if spec.per in ("site", "camera"):
            n = problem.ctx.n_sites if spec.per == "site" else problem.ctx.n_cameras
            if vals.size == n:
                starts.append({pname: vals})
            elif vals.size == 1:
                starts.append({pname: np.full(n, float(vals[0]))})
        elif vals.size:
            starts.append({pname: float(vals[0])})
    names = effect.param_names()
    if "az_deg" in names and problem.kind == "magnitude":
        for s in _bisector_starts(problem, ctx, z):
            starts.append(s)
            if "exponent" in names:
                starts.append({**s, "exponent": 300.0})
                starts.append({**s, "exponent": 30.0})
    layout = param_layout(effect, ctx)
    if layout.n >= 1 and effect.name not in _LINEAR:
        for _ in range(2):
            starts.append(effect.sample_params(rng, ctx))
    if effect.name == "clock_offset":
        # the sign is what the linear start can get wrong: try both of its magnitude
        for s in list(starts[1:2]):
            starts.append({"dt_s": -np.asarray(s["dt_s"])})
    return starts


def _grid_values(effect, problem):
    """Values of the integer / grid parameters to enumerate: list of dicts."""
    combos = [{}]
    for s in effect.params:
        if s.integer:
            n = problem.ctx.n_sensors if problem.kind == "css" else 1
            vals = list(range(int(n)))
        elif s.name == "t_start_s":
            tt = np.unique(problem.t)
            vals = list(np.quantile(tt, np.linspace(0.02, 0.9, 12))) if tt.size > 1 else [float(tt[0])]
        else:
            continue
        combos = [{**c, s.name: float(v)} for c in combos for v in vals]
    return combos


def params_to_json(fit, problem, effect_index: int) -> dict:
    """Fitted parameters of term ``effect_index`` with 1σ: {name: {value, sd, unit}}."""
    eff, params = fit.terms[effect_index]
    sds = {}
    if fit.sd is not None:
        for nm, sd in zip(fit.names, fit.sd):
            sds[nm] = float(sd)
    out = {}
    for s in eff.params:
        v = params[s.name]
        if np.ndim(v):
            if s.per in ("site", "camera") and problem.kind == "magnitude":
                keys = problem.site_names if s.per == "site" else problem.channel_names
            else:
                keys = [str(k) for k in range(len(v))]
            out[s.name] = {"unit": s.unit, "per": s.per, "values": {
                k: {"value": float(x), "sd": _nan_none(sds.get(f"{eff.name}.{s.name}[{k}]"))}
                for k, x in zip(keys, v)}}
        else:
            out[s.name] = {"unit": s.unit, "value": float(v),
                           "sd": _nan_none(sds.get(f"{eff.name}.{s.name}"))}
    return out


def _nan_none(x):
    return None if x is None or not np.isfinite(x) else float(x)


#: scan points per component for single-parameter effects (module docstring of _quick_starts)
_SCAN_POINTS = {"clock_offset": 241}


def _quick_starts(effect, problem, starts, base_fit):
    """Stage-1 starts: the linearised (or typical) start, the first geometric start, and for
    an effect with a single continuous parameter (scalar, or one value per site/camera/sensor)
    the best point of a scan of its bounds, component by component (41 points; 241 for a
    clock offset: for a fast rotator χ²(δt) has one basin per flash, ~0.05 s wide at 40°/s,
    and a shift of a whole flash period is far outside the reach of the linearised start)."""
    quick = starts[:2] if effect.name in _LINEAR else starts[:1]
    extra = [s for s in starts[1:] if "az_deg" in s][:1]
    quick = quick + extra
    L = param_layout(effect, problem.ctx)
    specs = {id(e[0]): e[0] for e in L.entries}
    if len(specs) != 1 or (L.n == 1 and effect.name in _LINEAR and L.entries[0][1] is None):
        return quick
    spec = L.entries[0][0]
    lo, hi = prior_bounds(spec)
    grid = np.linspace(lo, hi, _SCAN_POINTS.get(effect.name, 41))
    base = {**typical_params(effect, problem.ctx), **(quick[1] if len(quick) > 1 and effect.name in _LINEAR else {})}
    cur = base[spec.name]
    cur = np.array(cur, float, copy=True) if np.ndim(cur) else float(cur)
    best_c2 = None
    for _, comp in L.entries:
        best = None
        for v in grid:
            trial = cur
            if comp is None:
                trial = float(v)
            else:
                trial = np.array(cur, float, copy=True)
                trial[comp] = v
            try:
                pred = problem.predict(base_fit.theta, [(effect, {**base, spec.name: trial})])
            except Exception:  # pragma: no cover - defensive
                continue
            c2 = problem.chi2(pred)
            if best is None or c2 < best[0]:
                best = (c2, trial)
        if best is not None:
            best_c2, cur = best
    if best_c2 is not None:
        quick = quick + [{spec.name: cur}]
    return quick


def _fit_over_grid(eff, problem, base_fit, starts, nfev, rec, around=None):
    """Best fit over the integer/grid values (stage 1: all; refinement: the best only).

    Stage 1 records the profile ``[(grid values, χ²)]`` in ``rec["_profiles"]`` (for the
    profile-likelihood identification of grid parameters)."""
    best = None
    grid = _grid_values(eff, problem)
    gnames = {s.name for s in eff.params if s.integer or s.name in GRID_PARAMS}
    if around is not None and len(grid) > 1:
        # refine only at the best grid point of stage 1 — a step time at the resolution of
        # the data (_refine_step_time)
        fx = {k: v for k, v in around.terms[0][1].items() if k in gnames}
        if "t_start_s" in fx:
            fx = _refine_step_time(eff, problem, base_fit, around, fx, grid, rec)
        grid = [fx]
    profile = []
    for fixed in grid:
        try:
            f = fit_terms(problem, [eff], [[s] for s in starts], theta0=base_fit.theta,
                          max_nfev=nfev, fixed_effect_params=[fixed])
        except Exception as exc:
            rec.setdefault("errors", []).append(f"{type(exc).__name__}: {exc}")
            continue
        if fixed:
            profile.append((dict(fixed), float(f.chi2)))
        if best is None or f.chi2 < best.chi2:
            best = f
    if around is None and len(grid) > 1:
        rec["_profiles"] = profile
    return best


def _refine_step_time(eff, problem, base_fit, fit, fixed, grid, rec):
    """The step time between the grid values around the best one, at the resolution of the
    data: every distinct measurement time in (previous grid time, next grid time] is tried
    with the other parameters at ``fit``'s values; the profile gets these points too."""
    times = sorted({float(g["t_start_s"]) for g in grid})
    t0 = float(fixed["t_start_s"])
    i = times.index(t0) if t0 in times else int(np.argmin(np.abs(np.asarray(times) - t0)))
    lo = times[i - 1] if i > 0 else -np.inf
    hi = times[i + 1] if i + 1 < len(times) else np.inf
    tu = np.unique(problem.t)
    cand = tu[(tu > lo) & (tu <= hi)]
    params = dict(fit.terms[0][1])
    best = (float(fit.chi2), t0)
    prof = rec.setdefault("_profiles", [])
    for tt in cand:
        p = {**params, "t_start_s": float(tt)}
        try:
            c2 = problem.chi2(problem.predict(fit.theta if problem.n_free else None, [(eff, p)]))
        except Exception:  # pragma: no cover - defensive
            continue
        prof.append(({**fixed, "t_start_s": float(tt)}, float(c2)))
        if c2 < best[0]:
            best = (c2, float(tt))
    return {**fixed, "t_start_s": best[1]}


def held_values(effect, params) -> dict:
    """The values of the parameters fits hold fixed: integer and grid parameters at their
    values in ``params``; parameters in the effect's ``hold`` (held at their reference value
    because the data do not identify them) at their default."""
    specs = {s.name: s for s in effect.params}
    hold = set(getattr(effect, "hold", ()) or ())
    out = {}
    for k, v in params.items():
        if k not in held_names(effect):
            continue
        if k in hold:
            d = float(specs[k].default)
            out[k] = np.full(np.shape(v), d) if np.ndim(v) else d
        else:
            out[k] = v
    return out


def score_candidates(problem, base_fit, names=None, *, seed: int = 0, max_nfev: int = 60,
                     quick_nfev: int = 12, n_refine: int = 2, skip_reasons=None) -> list[dict]:
    """Score and rank effects (module docstring).

    Returns a list of dicts sorted by ΔBIC (largest first; not-applicable ones last):
    ``name``, ``description``, ``applicable``, ``reason``, ``signature_r``, ``delta_bic``,
    ``delta_chi2``, ``chi2_dof``, ``rms_mag`` (magnitudes) / ``rms`` (CSS), ``n_params``,
    ``params`` (with 1σ) and, internally, ``_fit`` (the :class:`~.baseline.Fit`).
    """
    from ..physics import available_effects

    rng = np.random.default_rng(seed)
    names = available_effects(problem.kind) if names is None else list(names)
    skip_reasons = dict(skip_reasons or {})
    ctx = problem.base_context(base_fit.theta)
    z0 = base_fit.z
    out = []
    for name in names:
        rec = {"name": name}
        t_start = None
        try:
            eff = diagnosis_effect(name, problem.ctx)
        except Exception as exc:  # pragma: no cover - registry problems
            rec.update(applicable=False, reason=f"cannot create: {exc}")
            out.append(rec)
            continue
        rec["description"] = eff.description
        if name in problem.exclude or name in skip_reasons:
            rec.update(applicable=False, reason=skip_reasons.get(
                name, "duplicates a free baseline parameter"))
            out.append(rec)
            continue
        try:
            sig_params = None
            if "az_deg" in eff.param_names() and problem.kind == "magnitude":
                sig_params = _bisector_starts(problem, ctx, z0, 1)[0]
            S = signature_matrix(eff, problem, ctx, sig_params)
            if not np.any(S != 0) and eff.params and sig_params is None \
                    and type(eff).signature is not Effect.signature:
                # the named signature is zero (e.g. 1 − ν of the geometric shadow when the
                # effect's parameter enlarges the shadow): use the change at typical values
                S = signature_matrix(eff, problem, ctx, {})
        except Exception as exc:
            rec.update(applicable=False, reason=f"not applicable: {type(exc).__name__}: {exc}")
            out.append(rec)
            continue
        if not np.any(S != 0):
            rec.update(applicable=False, reason="not applicable: its signature is zero on these data")
            out.append(rec)
            continue
        b, r = _regress(z0, S, problem.sigma)
        starts = candidate_starts(eff, problem, ctx, z0, S, b, rng)
        quick = _quick_starts(eff, problem, starts, base_fit)
        best = _fit_over_grid(eff, problem, base_fit, quick, quick_nfev, rec)
        if best is None:
            rec.update(applicable=False, reason="fit failed: " + "; ".join(rec.get("errors", [])))
            out.append(rec)
            continue
        rec.update(_fit=best, _starts=starts, _eff=eff, signature_r=r, _t=t_start)
        out.append(rec)
    # stage 2: the most promising candidates get every start and more iterations
    live = sorted([c for c in out if "_fit" in c], key=lambda c: c["_fit"].chi2)
    live = [c for c in live if bic_gain(base_fit.chi2, c["_fit"].chi2, problem.n,
                                        c["_fit"].n_effect_params) > 0]
    for c in live[:n_refine]:
        f = _fit_over_grid(c["_eff"], problem, base_fit,
                           [dict(c["_fit"].terms[0][1])] + c["_starts"], max_nfev, c,
                           around=c["_fit"])
        if f is not None and f.chi2 < c["_fit"].chi2:
            c["_fit"] = f
    for rec in out:
        if "_fit" not in rec:
            continue
        best = rec["_fit"]
        rec.pop("_t")
        rec["_fixed"] = held_values(rec["_eff"], best.terms[0][1])
        k = best.n_effect_params
        dof = max(problem.n - best.n_params, 1)
        rec.update(applicable=True, reason="",
                   delta_bic=bic_gain(base_fit.chi2, best.chi2, problem.n, k),
                   delta_chi2=float(base_fit.chi2 - best.chi2), chi2_dof=best.chi2 / dof,
                   n_params=k, params=params_to_json(best, problem, 0))
        rec["rms_mag" if problem.kind == "magnitude" else "rms"] = best.rms(problem.y)
    out.sort(key=lambda c: (not c.get("applicable", False),
                            -(c.get("delta_bic") if np.isfinite(c.get("delta_bic", np.nan)) else -np.inf)))
    for i, c in enumerate(out):
        c["rank"] = i + 1 if c.get("applicable") else None
    return out
