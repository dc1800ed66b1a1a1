"""Orchestration of a diagnosis: baseline → residuals → candidates → held-out selection → verdict.

Steps (:func:`diagnose`):

1. fit the baseline (:func:`~.baseline.fit_baseline`: only the parameters the user frees);
2. standardised residuals; consistency (:func:`~.residuals.consistency`: χ²/dof not above
   its 99.8 % band and white residuals, or χ²/dof ≤ 1 — a fit at or below the noise is never
   a mismatch); where the residuals are systematic (:func:`~.residuals.find_segments`);
3. cross-validation folds over whatever the recording has (:mod:`.folds`: objects, nights,
   passes or contiguous time blocks; or the grouping the user asks for). When no folds are
   possible the diagnosis says so (screen and ``diagnosis.json``) and falls back to the
   in-sample ΔBIC > ``min_gain`` for choosing;
4. every registry effect of the problem's kind is scored and fitted alone
   (:func:`~.candidates.score_candidates`), and the surface refit (:mod:`.surface`) joins as
   one more candidate;
5. greedy search by held-out gain (:mod:`.selection`): each remaining candidate is fitted
   jointly with the model so far — in-sample and fold by fold — and the one with the largest
   held-out gain G is added if G > ``min_gain`` and its parameters are identified
   (:mod:`.identify`). When the candidate with the largest G is not identified, it is
   reported as "fits, but unidentifiable with these data" and the search stops: naming a
   lesser, identified candidate would present an inferior explanation as the answer. A fixable parameter (``ParamSpec.fixable``,
   e.g. the penumbra's atmospheric shadow height) that the data do not identify is held at its
   reference value and the candidate refitted before it is judged; so are single components
   of a per-site/camera/sensor parameter that the data hardly constrain
   (:func:`~.identify.weak_components`: e.g. the elevation misalignment of a sensor that
   sees the Sun only briefly). When no candidate is
   identified alone (with two effects present, each one fitted alone leaves the other's
   misfit, and the covariance scaled by that χ²/dof hides what the data identify), the best
   candidate is fitted jointly with each of the next best effects (``pair_candidates`` in
   all); the first pair whose members are both identified, with a held-out gain above
   ``min_gain`` and above either member's alone, is named (:func:`_joint_pair`);
6. verdict: ``consistent`` when the baseline already explains the recording, ``mismatch``
   otherwise; the final model is the baseline plus the named effects. Further groupings
   (``cv_report``) re-evaluate the baseline and the final model held out, for the report.

:func:`diagnose_recording` builds the problem from files (HDF5 lightcurve, CSV + scenario, or
a CSS recording); :func:`load_problem` is the same without diagnosing (used by
:mod:`.transfer` to apply a fitted model to new recordings).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..report.views import DiagnosisViews
from .baseline import bic_gain, fit_baseline, fit_terms
from .candidates import score_candidates
from .folds import DEFAULT_FOLDS, make_folds
from .identify import identify_free, identify_term, weak_components
from .residuals import consistency, find_segments
from .selection import (MIN_GAIN, Model, cv_predict, folds_improved, gain_standard_error,
                        held_out_gain, held_out_summary)
from .surface import SURFACE_DESCRIPTION, identifiable_subset, surface_free_params

__all__ = ["Diagnosis", "diagnose", "diagnose_recording", "TIMING_EFFECTS", "load_model_scenario",
           "diagnose_css_recording", "load_problem", "SURFACE"]

TIMING_EFFECTS = ("light_time", "clock_offset", "exposure_smearing")
#: name of the surface-refit candidate
SURFACE = "surface"


@dataclass(repr=False)
class Diagnosis(DiagnosisViews):
    """Everything :func:`~.report.write_report` needs (views: short repr, ``_repr_html_``,
    ``to_pandas("candidates" | "segments")``)."""

    problem: object
    verdict: str
    baseline_fit: object
    baseline_check: dict
    segments: list
    candidates: list
    chosen: list
    final_fit: object
    final_check: dict
    final_model: object = None
    folds: object = None
    cv_reason: str | None = None
    steps: list = field(default_factory=list)
    unidentified: list = field(default_factory=list)
    cross_validation: dict | None = None
    notes: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """The ``diagnosis.json`` content (schema in :mod:`.report`)."""
        from .report import diagnosis_json

        return diagnosis_json(self)

    def to_pandas(self, table="candidates"):
        """``"candidates"``: one row per candidate (:func:`~.report.candidates_table`: first
        step's in-sample and held-out numbers, identified, decision); ``"segments"``: the time
        spans, sites and geometry regimes tested."""
        if table != "candidates":
            return super().to_pandas(table)
        from ..report.views import require_pandas
        from .report import candidates_table

        pd = require_pandas()
        return pd.DataFrame(candidates_table(self.summary())).set_index("name")


def _in_sample(problem, fit, ref_fit):
    dof = max(problem.n - fit.n_params, 1)
    k = max(fit.n_params - ref_fit.n_params, 0)
    return {"chi2_dof": fit.chi2 / dof, "rms": fit.rms(problem.y),
            "delta_chi2": float(ref_fit.chi2 - fit.chi2),
            "delta_bic": bic_gain(ref_fit.chi2, fit.chi2, problem.n, k), "n_params_added": int(k)}


def _surface_trial(current, cand, max_nfev):
    """Fit the current model with the identifiable surface parameters freed."""
    prob = current.problem
    extra = surface_free_params(prob)
    if not extra:
        return None, "every surface parameter is already free (or the shape has none)"
    terms = current.fit.terms
    kept, dropped = identifiable_subset(prob, current.fit.theta, extra, terms)
    cand["_dropped"] = [(p.name, why) for p, why in dropped]
    if not kept:
        return None, "the data identify none of the surface parameters"
    prob2 = prob.with_free(list(prob.free) + kept)
    theta0 = np.r_[current.fit.theta, [p.x0 for p in kept]]
    fit = fit_terms(prob2, current.effects, current.starts(), theta0=theta0, max_nfev=max_nfev,
                    fixed_effect_params=current.fixed or None)
    return Model(prob2, list(current.effects), list(current.fixed), fit,
                 current.names + [SURFACE]), [p.name for p in kept]


def _effect_trial(current, cand, max_nfev, first):
    from .candidates import held_values

    eff = cand["_eff"]
    single = cand["_fit"]
    fixed = held_values(eff, single.terms[0][1])
    if first and not current.effects and current.problem is cand["_problem"]:
        fit = single
    else:
        starts = [[dict(p) for _, p in current.fit.terms] + [dict(single.terms[0][1])]]
        fit = fit_terms(current.problem, current.effects + [eff], starts,
                        theta0=current.fit.theta if current.problem.n_free else None,
                        max_nfev=max_nfev, fixed_effect_params=current.fixed + [fixed])
    return Model(current.problem, current.effects + [eff], current.fixed + [fixed], fit,
                 current.names + [cand["name"]])


def _refit_holding(model, eff_index, names, max_nfev):
    """Refit ``model`` with the fixable parameters ``names`` of one effect held at defaults."""
    eff = model.effects[eff_index]
    eff.hold = frozenset(set(eff.hold) | set(names))
    specs = {s.name: s for s in eff.params}
    fixed = [dict(f) for f in model.fixed]
    for nm in names:
        v = model.fit.terms[eff_index][1][nm]
        d = specs[nm].default
        fixed[eff_index][nm] = np.full(np.shape(v), d) if np.ndim(v) else float(d)
    starts = [[dict(p) for _, p in model.fit.terms]]
    fit = fit_terms(model.problem, model.effects, starts,
                    theta0=model.fit.theta if model.problem.n_free else None,
                    max_nfev=max_nfev, fixed_effect_params=fixed)
    return Model(model.problem, model.effects, fixed, fit, model.names)


def _refit_holding_components(model, eff_index, comps, max_nfev):
    """Refit ``model`` with components ``comps`` ({name: indices}) of one effect's
    per-site/camera/sensor parameters held at their reference (null) value."""
    eff = model.effects[eff_index]
    specs = {s.name: s for s in eff.params}
    hc = {k: frozenset(v) for k, v in (getattr(eff, "hold_components", None) or {}).items()}
    fixed = [dict(f) for f in model.fixed]
    terms = [dict(p) for _, p in model.fit.terms]
    for nm, idx in comps.items():
        hc[nm] = frozenset(set(hc.get(nm, ())) | set(idx))
        ref = specs[nm].null if specs[nm].null is not None else specs[nm].default
        v = np.array(terms[eff_index][nm], float, copy=True)
        v[sorted(hc[nm])] = ref
        terms[eff_index][nm] = v
        fixed[eff_index][nm] = v
    eff.hold_components = hc
    fit = fit_terms(model.problem, model.effects, [terms],
                    theta0=model.fit.theta if model.problem.n_free else None,
                    max_nfev=max_nfev, fixed_effect_params=fixed)
    return Model(model.problem, model.effects, fixed, fit, model.names)


def _identify(model, cand, first):
    if cand["name"] == SURFACE:
        return identify_free(model.fit, set(cand.get("_kept", ())))
    return identify_term(model.fit, len(model.effects) - 1,
                         profiles=cand.get("_profiles") if first else None)


def _fixable_failures(ident, eff):
    fx = {s.name for s in eff.params if s.fixable}
    bad = {k.split("[", 1)[0] for k, r in ident["params"].items() if not r.get("ok", True)}
    return bad if bad and bad <= fx else set()


def _evaluate(current, cand, folds, cur_hs, *, max_nfev, cv_nfev, first):
    """One candidate at one step: joint fit, identification, in-sample and held-out numbers."""
    rec = {"name": cand["name"]}
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        if cand["name"] == SURFACE:
            model, kept = _surface_trial(current, cand, max_nfev)
            if model is None:
                rec.update(applicable=False, reason=kept)
                return rec, None
            cand["_kept"] = kept
        else:
            model = _effect_trial(current, cand, max_nfev, first)
        ident = _identify(model, cand, first)
        if not ident["identified"] and cand["name"] != SURFACE:
            held = _fixable_failures(ident, cand["_eff"])
            if held:
                model = _refit_holding(model, len(model.effects) - 1, held, max_nfev)
                ident = _identify(model, cand, first)
        if not ident["identified"] and cand["name"] != SURFACE:
            weak = weak_components(model.fit, len(model.effects) - 1, ident)
            if weak:
                model = _refit_holding_components(model, len(model.effects) - 1, weak, max_nfev)
                ident = _identify(model, cand, first)
    rec.update(applicable=True, identified=ident["identified"], identification=ident,
               in_sample=_in_sample(model.problem, model.fit, current.fit))
    _score(rec, model, folds, cur_hs, cv_nfev)
    return rec, model


def _score(rec, model, folds, cur_hs, cv_nfev):
    """Put the held-out numbers of ``model`` (and its gain over ``cur_hs``) into ``rec``;
    without folds the gain is the in-sample ΔBIC of ``rec["in_sample"]``."""
    if folds is not None:
        cv = cv_predict(model, folds, max_nfev=cv_nfev)
        hs = held_out_summary(model.problem, cv["pred"], folds, cv["pred_var"])
        hs["gain"] = held_out_gain(cur_hs, hs)
        hs["folds_improved"] = folds_improved(cur_hs, hs)
        hs["n_folds"] = folds.n_folds
        hs["fold_params"] = cv["fold_params"]
        rec["held_out"] = hs
        rec["gain"] = hs["gain"]
    else:
        rec["gain"] = rec["in_sample"]["delta_bic"]


def _one_standard_error(ok):
    """Reorder ``ok`` (sorted by gain) so that the identified candidate with the fewest
    parameters among those within one standard error of the best gain comes first
    (:mod:`.selection`)."""
    if len(ok) < 2 or "held_out" not in ok[0]:
        return
    best = ok[0]
    se = gain_standard_error(best["held_out"])
    tied = [r for r in ok if "held_out" in r and r["gain"] > 0 and r.get("identified")
            and best["gain"] - r["gain"] <= se]
    if len(tied) < 2:
        return
    simplest = min(tied, key=lambda r: (r["in_sample"]["n_params_added"], -r["gain"]))
    if simplest is not best:
        ok.remove(simplest)
        ok.insert(0, simplest)
        simplest["one_se_rule"] = (f"within one standard error of {best['name']}'s held-out gain "
                                   "with fewer parameters")


def _joint_pair(current, ok, models, by_name, folds, cur_hs, *, min_gain, n_top, max_nfev,
                cv_nfev):
    """Two effects fitted together when the best is not identified alone (module docstring, step 5).

    ``ok``: the first step's records (best held-out gain first); ``models``: their fitted
    models. The best candidate (an effect, not the surface refit) is fitted jointly with each
    of the next ``n_top - 1`` effects whose gain alone exceeds ``min_gain``, in the order of
    those gains — the best explanation must be part of what is named, as in every step; the
    first pair whose members' parameters are BOTH identified in the joint fit, with a held-out
    gain above ``min_gain`` and above either member's alone, is named. Returns ``(model,
    [record of the best, record of its partner])`` or None.
    """
    top = [r for r in ok if r["gain"] > min_gain and r["name"] != SURFACE
           and r["name"] in models][:n_top]
    if len(top) < 2 or top[0].get("identified"):
        return None
    if top[0] is not ok[0]:
        return None            # the best explanation is the surface refit: no effect pair
    ra, a = top[0], by_name[top[0]["name"]]
    best = None
    for rb in top[1:]:
        # components held in the single fits (their uncertainty inflated by the other effect's
        # misfit) are judged afresh in the joint fit
        a["_eff"].hold_components = {}
        by_name[rb["name"]]["_eff"].hold_components = {}
        try:
            rec, model = _evaluate(models[ra["name"]], by_name[rb["name"]], folds, cur_hs,
                                   max_nfev=max_nfev, cv_nfev=cv_nfev, first=False)
        except Exception:  # pragma: no cover - a failing pair is skipped
            continue
        if model is None or not rec.get("identified"):
            continue
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            ident_a = identify_term(model.fit, 0, profiles=a.get("_profiles"))
            weak = {} if ident_a["identified"] else weak_components(model.fit, 0, ident_a)
            if weak:
                model = _refit_holding_components(model, 0, weak, max_nfev)
                ident_a = identify_term(model.fit, 0, profiles=a.get("_profiles"))
                ident_b = identify_term(model.fit, 1)
                rec.update(identified=ident_b["identified"], identification=ident_b,
                           in_sample=_in_sample(model.problem, model.fit, current.fit))
                _score(rec, model, folds, cur_hs, cv_nfev)
        if not rec["identified"]:
            continue
        # the pair against the baseline (the record was scored against the first alone)
        rec["in_sample"] = _in_sample(model.problem, model.fit, current.fit)
        if folds is None:
            rec["gain"] = rec["in_sample"]["delta_bic"]
        gain = rec["gain"]
        if ident_a["identified"] and np.isfinite(gain) and gain > min_gain \
                and gain > max(ra["gain"], rb["gain"]):
            best = (model, rb, rec, ident_a)
            break
    if best is None:
        return None
    model, rb, rec_b, ident_a = best
    why = (f"added jointly with {{}}: {ra['name']} is not identified alone (fitted alone, the "
           "other effect's misfit inflates its uncertainty); both are identified fitted together")
    rec_a = {k: v for k, v in rec_b.items() if k not in ("name", "identification")}
    rec_a.update(name=ra["name"], identification=ident_a, identified=True,
                 decision=why.format(rb["name"]))
    rec_b["decision"] = why.format(ra["name"])
    return model, [rec_a, rec_b]


def diagnose(problem, *, folds="auto", n_folds: int = DEFAULT_FOLDS, min_gain: float = MIN_GAIN,
             max_effects: int = 2, pair_candidates: int = 3, surface: bool = True,
             cv_report=(), skip_reasons=None, seed: int = 0, max_nfev: int = 60,
             cv_nfev: int = 30, progress=None) -> Diagnosis:
    """Run the diagnosis of ``problem`` (module docstring). Its fits are small dense
    least-squares problems: with a multi-threaded OpenBLAS, call
    :func:`lightcurve.studies.runner.limit_blas_threads` first (``lightcurve diagnose`` does;
    4× less CPU on a loaded 2-core machine).

    ``folds``: grouping for the selection ("auto" or one of :data:`~.folds.GROUPINGS`, or
    None for no cross-validation); ``n_folds``: number of folds; ``min_gain``: held-out gain
    needed to add a candidate (ΔBIC without folds); ``max_effects``: at most this many
    additions; ``pair_candidates``: candidates tried at later steps (the best by the first
    step's held-out gain); ``surface``: include the surface refit candidate; ``cv_report``:
    further groupings to report held-out numbers for; ``progress``: callable(str) or None.
    """
    say = progress or (lambda s: None)
    tim = {}
    t0 = time.perf_counter()
    notes = []
    say("fitting the baseline")
    base = fit_baseline(problem)
    chk0 = consistency(base.z, problem.t, base.n_params)
    segs = find_segments(problem, base.z)
    fo, cv_reason = (None, "cross-validation switched off") if folds is None else \
        make_folds(problem, folds, n_folds)
    if fo is None:
        say(f"{cv_reason}; effects are chosen by in-sample ΔBIC")
    else:
        say(f"cross-validation: {fo.describe()}")
    tim["baseline_s"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    say(f"baseline chi2/dof {chk0['chi2_dof']:.3g}; fitting every candidate effect")
    cands = score_candidates(problem, base, seed=seed, max_nfev=max_nfev, skip_reasons=skip_reasons)
    for c in cands:
        c["kind"] = "effect"
        c["_problem"] = problem
    if surface and problem.kind == "magnitude":
        sc = {"name": SURFACE, "kind": "surface", "description": SURFACE_DESCRIPTION}
        if SURFACE in (skip_reasons or {}):
            sc.update(applicable=False, reason=skip_reasons[SURFACE])
        else:
            sc["applicable"] = True
        cands.append(sc)
    tim["candidates_s"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    current = Model(problem, [], [], base, [])
    base_hs = cur_hs = None
    if fo is not None:
        base_cv = cv_predict(current, fo, max_nfev=cv_nfev)
        base_hs = cur_hs = held_out_summary(problem, base_cv["pred"], fo, base_cv["pred_var"])
    steps, chosen, unidentified = [], [], []
    chk = chk0
    by_name = {c["name"]: c for c in cands}
    pool = [c for c in cands if c.get("applicable")]
    step = 0
    while not chk["consistent"] and len(chosen) < max_effects and pool:
        step += 1
        say(f"step {step}: {len(pool)} candidate(s), held-out gain over "
            f"{'+'.join(chosen) or 'the baseline'}")
        recs, models = [], {}
        for c in pool:
            try:
                rec, model = _evaluate(current, c, fo, cur_hs, max_nfev=max_nfev,
                                       cv_nfev=cv_nfev, first=step == 1)
            except Exception as exc:  # pragma: no cover - a failing candidate is reported
                rec, model = {"name": c["name"], "applicable": False,
                              "reason": f"fit failed: {type(exc).__name__}: {exc}"}, None
            rec["step"] = step
            recs.append(rec)
            if model is not None:
                models[c["name"]] = model
            c.setdefault("steps", []).append(rec)
        ok = [r for r in recs if r.get("applicable") and np.isfinite(r.get("gain", np.nan))]
        ok.sort(key=lambda r: -r["gain"])
        _one_standard_error(ok)
        pick = None
        top = ok[0] if ok else None
        for r in ok:
            if r["gain"] <= min_gain:
                r["decision"] = "held-out gain too small" if fo is not None else "ΔBIC too small"
                continue
            if not r["identified"]:
                r["decision"] = "fits, but unidentifiable with these data"
                if r["name"] not in [u["name"] for u in unidentified]:
                    unidentified.append({"name": r["name"], "step": step, "gain": r["gain"],
                                         "reasons": r["identification"]["reasons"]})
                continue
            if pick is None and r is top:
                pick = r
                r["decision"] = "added" + (f" ({r['one_se_rule']})" if "one_se_rule" in r else "")
            elif pick is None:
                # the best explanation is not identifiable: a lesser one would mislead
                r["decision"] = f"not named: {top['name']} explains more but is unidentifiable"
            else:
                r["decision"] = "smaller held-out gain than " + pick["name"]
        steps.append({"step": step, "base": list(chosen), "records": recs})
        if pick is None and not chosen and max_effects >= 2:
            joint = _joint_pair(current, ok, models, by_name, fo, cur_hs, min_gain=min_gain,
                                n_top=pair_candidates, max_nfev=max_nfev, cv_nfev=cv_nfev)
            if joint is not None:
                step += 1
                model, jrecs = joint
                for r in jrecs:
                    r["step"] = step
                    by_name[r["name"]].setdefault("steps", []).append(r)
                steps.append({"step": step, "base": [], "records": jrecs, "joint": True})
                current = model
                chosen.extend(r["name"] for r in jrecs)
                unidentified[:] = [u for u in unidentified if u["name"] not in chosen]
                chk = consistency(current.fit.z, current.problem.t, current.fit.n_params)
                if fo is not None:
                    cv = cv_predict(current, fo, max_nfev=cv_nfev)
                    cur_hs = held_out_summary(current.problem, cv["pred"], fo, cv["pred_var"])
                break
        if pick is None:
            break
        current = models[pick["name"]]
        chosen.append(pick["name"])
        chk = consistency(current.fit.z, current.problem.t, current.fit.n_params)
        if fo is not None:
            cv = cv_predict(current, fo, max_nfev=cv_nfev)
            cur_hs = held_out_summary(current.problem, cv["pred"], fo, cv["pred_var"])
        # later steps: the most promising of the rest (by this step's gain)
        rest = [r["name"] for r in ok if r["name"] != pick["name"] and r["gain"] > 0]
        pool = [by_name[n] for n in rest[:pair_candidates]]
    tim["selection_s"] = time.perf_counter() - t2
    verdict = "consistent" if chk0["consistent"] else "mismatch"
    d = Diagnosis(problem=problem, verdict=verdict, baseline_fit=base, baseline_check=chk0,
                  segments=segs, candidates=cands, chosen=chosen, final_fit=current.fit,
                  final_check=chk, final_model=current, folds=fo, cv_reason=cv_reason,
                  steps=steps, unidentified=unidentified, notes=notes)
    t3 = time.perf_counter()
    d.cross_validation = _cross_validation(d, base_hs, cur_hs, cv_report, n_folds, cv_nfev, say)
    tim["cv_report_s"] = time.perf_counter() - t3
    tim["total_s"] = time.perf_counter() - t0
    d.timings = tim
    return d


def _cross_validation(d, base_hs, final_hs, cv_report, n_folds, cv_nfev, say):
    """Held-out numbers of the baseline and the final model, for the selection folds and
    any further groupings asked for."""
    out = {"possible": d.folds is not None, "reason": d.cv_reason, "schemes": []}
    if d.folds is not None:
        out["selection"] = d.folds.as_dict()
        out["gain_statistic"] = ("G = n ln(chi2_held(before)/chi2_held(after)): held-out Gaussian "
                                 "log-likelihood ratio x2, noise scale profiled")
        out["schemes"].append(_scheme(d.folds, base_hs, final_hs))
    base_model = Model(d.problem, [], [], d.baseline_fit, [])
    for g in cv_report:
        if d.folds is not None and g == d.folds.grouping:
            continue
        fo, why = make_folds(d.problem, g, n_folds)
        if fo is None:
            out["schemes"].append({"grouping": g, "possible": False, "reason": why})
            continue
        say(f"held-out check: {fo.describe()}")
        cb = cv_predict(base_model, fo, max_nfev=cv_nfev)
        b = held_out_summary(d.problem, cb["pred"], fo, cb["pred_var"])
        fm = d.final_model
        cf = cv_predict(fm, fo, max_nfev=cv_nfev)
        f = held_out_summary(fm.problem, cf["pred"], fo, cf["pred_var"])
        out["schemes"].append(_scheme(fo, b, f))
    return out


def _scheme(fo, b, f):
    return {"grouping": fo.grouping, "method": fo.method, "possible": True,
            "n_groups": fo.n_groups, "n_folds": fo.n_folds,
            "baseline": {k: b[k] for k in ("rms", "chi2_per_n", "r", "n_unpredicted")},
            "final": {k: f[k] for k in ("rms", "chi2_per_n", "r", "n_unpredicted")},
            "gain": held_out_gain(b, f)}


# ----------------------------------------------------------------------------------------
# from files
# ----------------------------------------------------------------------------------------
def load_model_scenario(path, *, library_dirs=None, site_dirs=None, shape=None):
    """Load a scenario TOML for diagnosis: the scenario with its ``[effects]`` switched off
    (the model whose missing physics is being looked for) and the ``[diagnosis]`` table, if
    any (keys ``free`` (list of words, see :func:`~.problem.parse_free`), ``exclude`` (effect
    names, or "surface", not to propose), ``max_effects`` (1 or 2), ``min_gain`` (> 0)).
    Returns ``(scenario, options)``. ``library_dirs``/``site_dirs``: extra shape-library and
    observatory folders; ``shape``: a resolved Shape replacing the scenario's ``[shape]``."""
    from pathlib import Path

    from ..errors import InputError
    from ..io.tomlio import Section, load_toml
    from ..physics import available_effects
    from ..studies.scenario import parse_scenario

    path = Path(path)
    doc, text = load_toml(path, with_text=True)
    diag = doc.pop("diagnosis", None)
    had_effects = bool(doc.pop("effects", None))
    sc = parse_scenario(doc, file=path, text=text, library_dirs=library_dirs,
                        site_dirs=site_dirs, shape=shape)
    opts = {}
    if diag is not None:
        sec = Section(diag, file=path, name="diagnosis")
        free = sec.raw("free", None)
        if free is not None:
            if not isinstance(free, list) or not all(isinstance(w, str) for w in free):
                raise InputError("expected a list of names", file=path, field="diagnosis.free", value=free)
            opts["free"] = ",".join(free) if free else "none"
        ex = sec.raw("exclude", None)
        if ex is not None:
            allowed = available_effects() + [SURFACE]
            if not isinstance(ex, list) or any(e not in allowed for e in ex):
                raise InputError("expected a list of effect names", file=path, field="diagnosis.exclude",
                                 value=ex, allowed=", ".join(allowed))
            opts["exclude"] = list(ex)
        opts["max_effects"] = sec.int("max_effects", 2, min=1, max=2)
        opts["min_gain"] = sec.float("min_gain", MIN_GAIN, min=0.0, min_open=True)
        sec.check_unknown()
    opts["model_had_effects"] = had_effects
    return sc, opts


def load_problem(recording, scenario=None, *, free=None, exclude=(), shape=None,
                 library_dirs=None, site_dirs=None):
    """The diagnosis problem of one magnitude recording file — or of several, one object each
    (a list of paths: :func:`~.problem.combine_problems`, so that objects can be held out) —
    and the model it is checked against. Returns ``(problem, skip_reasons, options, notes)``;
    :func:`_load_one` documents the single-file case."""
    from pathlib import Path

    from .problem import combine_problems, parse_free, with_free_words

    if isinstance(recording, (str, Path)):
        return _load_one(recording, scenario, free=free, exclude=exclude, shape=shape,
                         library_dirs=library_dirs, site_dirs=site_dirs)
    recs = [Path(r) for r in recording]
    if len(recs) == 1:
        return _load_one(recs[0], scenario, free=free, exclude=exclude, shape=shape,
                         library_dirs=library_dirs, site_dirs=site_dirs)
    loaded = [_load_one(r, scenario, free="none", exclude=exclude, shape=shape,
                        library_dirs=library_dirs, site_dirs=site_dirs) for r in recs]
    probs = [x[0] for x in loaded]
    names = []
    for r in recs:
        nm = r.stem
        while nm in names:
            nm += "'"
        names.append(nm)
    prob = combine_problems(probs, names)
    skip = {}
    for x in loaded:
        skip.update(x[1])
    opts = loaded[0][2]
    words = parse_free(free if free is not None else opts.get("free", "none"), prob.ctx.shape)
    prob = with_free_words(prob, words)
    notes = [f"{len(recs)} recordings, one object each: {', '.join(names)} (times from "
             f"{prob.ctx.epoch_utc})",
             f"free baseline parameters: {', '.join(p.name for p in prob.free) or 'none'}"]
    notes += [n for x in loaded for n in x[3] if not n.startswith("free baseline")][:5]
    return prob, skip, opts, notes


def _load_one(recording, scenario=None, *, free=None, exclude=(), shape=None,
              library_dirs=None, site_dirs=None):
    """The diagnosis problem of a magnitude recording file and the model it is checked against.

    ``recording``: our lightcurve HDF5 (model = the file's own scenario — with the shape and
    sites the file carries — or ``scenario``; attitude = the file's truth, else the model's
    attitude from the scenario epoch) or a CSV recording (needs ``scenario``; attitude = the
    scenario's law or noise-free dynamics). ``free``: comma-separated words
    (:func:`~.problem.parse_free`), default ``none``: refitting the object's surfaces is a
    candidate that competes on held-out gain (:mod:`.surface`), never silently on. ``shape``
    (a Shape, library name or shape TOML) replaces the model's shape; ``library_dirs`` /
    ``site_dirs`` are extra shape-library and observatory folders. Files without truth that
    give exposure times are modelled with the model's body rates, so the timing effects are
    evaluated for them. A file with a photometric band (``attrs["band"]``) is modelled with
    that band's Sun magnitude (``attrs["sun_mag"]``). Returns ``(problem, skip_reasons,
    options, notes)``.
    """
    from pathlib import Path

    from ..errors import InputError
    from ..studies.evaluate import model_attitude
    from ..studies.scenario import scenario_from_lightcurve
    from .problem import magnitude_problem, parse_free

    recording = Path(recording)
    opts = {}
    notes = []
    if shape is not None and not hasattr(shape, "n_facets"):
        from ..photometry import load_shape

        shape = load_shape(str(shape), library_dirs=library_dirs)
    if recording.suffix.lower() in (".h5", ".hdf5"):
        from ..io.lightcurve_h5 import read_lightcurve

        lc = read_lightcurve(recording)
        if scenario is not None:
            sc, opts = load_model_scenario(scenario, library_dirs=library_dirs,
                                           site_dirs=site_dirs, shape=shape)
        else:
            sc = scenario_from_lightcurve(lc, recording, drop=("effects", "diagnosis"),
                                          library_dirs=library_dirs, site_dirs=site_dirs,
                                          shape=shape)
        q = lc.truth_q
        omega = lc.truth_omega_rad_s
        if q is None:
            q, omega = model_attitude(sc, lc, return_omega=True)
    else:
        if scenario is None:
            raise InputError("a CSV recording needs --scenario MODEL.toml (shape, attitude, sites)",
                             file=recording)
        sc, opts = load_model_scenario(scenario, library_dirs=library_dirs, site_dirs=site_dirs,
                                       shape=shape)
        from ..io.recording import read_recording

        # rows in the Earth's full shadow are kept (counted, warned) for shadow/clock effects
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lc = read_recording(recording, sc, unlit="keep", site_dirs=site_dirs)
        q, omega = model_attitude(sc, lc, return_omega=True)
    if not lc.has_truth and (lc.exposure_s is None or not np.any(np.isfinite(lc.exposure_s))):
        omega = None  # no exposure times: the timing effects stay off (docstring)
    words = parse_free(free if free is not None else opts.get("free", "none"), sc.shape)
    skip = {}
    if omega is None:
        for name in TIMING_EFFECTS:
            skip[name] = ("not applicable: evaluating the model at shifted times needs the body "
                          "rate and the object's velocity, unknown for this recording")
    for name in list(exclude) + list(opts.get("exclude", [])):
        skip[name] = "excluded by the user"
    sun_mag = float(lc.attrs["sun_mag"]) if "band" in (lc.attrs or {}) else sc.measurement.sun_mag
    prob = magnitude_problem(lc, sc.shape, q=q, omega=omega, sun_mag=sun_mag,
                             ignore_eclipse=sc.measurement.ignore_eclipse, free=words,
                             label=recording.name)
    if sc.measurement.ignore_eclipse:
        # the model ignores the eclipse: umbra epochs are modelled as sunlit; the penumbra
        # effect then means "switch the partial solar disc (and the umbra) on"
        prob.ctx = prob.ctx.with_state(ignore_eclipse=True)
    notes.append(f"free baseline parameters: {', '.join(p.name for p in prob.free) or 'none'}")
    if opts.get("model_had_effects"):
        notes.append("the scenario's [effects] table was switched off for the model")
    return prob, skip, opts, notes


def diagnose_recording(recording, scenario=None, *, free=None, exclude=(), progress=None,
                       folds="auto", n_folds=DEFAULT_FOLDS, cv_report=(), max_effects=None,
                       min_gain=None, seed=0, shape=None, library_dirs=None, site_dirs=None):
    """Diagnose a recording file (or several, one object each) against a model
    (:func:`load_problem`; a CSS recording, detected from the file, goes to
    :func:`diagnose_css_recording`). Returns a :class:`Diagnosis`."""
    from pathlib import Path

    from ..errors import InputError
    from .css_recording import is_css_recording

    recs = [recording] if isinstance(recording, (str, Path)) else list(recording)
    css = [is_css_recording(Path(r)) for r in recs]
    if any(css):
        if len(recs) > 1:
            raise InputError("CSS recordings are diagnosed one at a time", field="recording",
                             value=", ".join(map(str, recs)))
        return diagnose_css_recording(Path(recs[0]), scenario, free=free, exclude=exclude,
                                      progress=progress, max_effects=max_effects,
                                      min_gain=min_gain, seed=seed, folds=folds, n_folds=n_folds)
    prob, skip, opts, notes = load_problem(recording, scenario, free=free, exclude=exclude,
                                           shape=shape, library_dirs=library_dirs,
                                           site_dirs=site_dirs)
    d = diagnose(prob, progress=progress, folds=folds, n_folds=n_folds, cv_report=cv_report,
                 skip_reasons=skip, max_effects=max_effects or opts.get("max_effects", 2),
                 min_gain=min_gain or opts.get("min_gain", MIN_GAIN), seed=seed)
    d.notes.extend(notes)
    return d


def diagnose_css_recording(recording, configuration=None, *, free=None, exclude=(), progress=None,
                           max_effects=None, min_gain=None, seed=0, max_epochs=400,
                           folds="auto", n_folds=DEFAULT_FOLDS):
    """Diagnose a CSS recording (:mod:`.css_recording`) against the sensors' direct-Sun model.

    ``configuration``: optional CSS configuration TOML (the model's nominal sensors; the
    file's are used otherwise). The baseline has no free parameters (``free`` must be None
    or ``none``); the ``css_*`` effects are the candidates; folds are contiguous time blocks.
    """
    from ..errors import InputError
    from .css_recording import css_recording_problem

    if free not in (None, "none"):
        raise InputError("a CSS baseline has no free parameters", field="--free", value=free,
                         allowed="none")
    prob, notes = css_recording_problem(recording, configuration=configuration,
                                        max_epochs=max_epochs)
    skip = {name: "excluded by the user" for name in exclude}
    d = diagnose(prob, progress=progress, skip_reasons=skip, folds=folds, n_folds=n_folds,
                 max_effects=max_effects or 2, min_gain=min_gain or MIN_GAIN, seed=seed)
    d.notes.extend(notes)
    d.notes.append("model: nominal sensors, direct Sun only (no albedo, nominal scale factors "
                   "and normals), attitude and orbit from the recording")
    return d
