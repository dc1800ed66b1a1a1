"""Orchestration of a diagnosis: baseline → residual analysis → candidates → refit → verdict.

Steps (:func:`diagnose`):

1. fit the baseline (:func:`~.baseline.fit_baseline`: the free parameters the user marks);
2. standardised residuals; consistency = χ²/dof inside its two-sided 99.8 % band and the
   Ljung–Box and runs tests passing at 0.1 % (:func:`~.residuals.consistency`; false-alarm
   rate ≤ 0.4 % for white N(0,1) residuals); systematic segments
   (:func:`~.residuals.find_segments`);
3. score and rank every registered effect (:func:`~.candidates.score_candidates`);
4. if the baseline is not consistent: take the best candidate when its ΔBIC > ``min_delta_bic``
   (10: "very strong" evidence); if the residuals are still not consistent, refit it jointly
   with each of the next few candidates and keep the best pair when it gains another
   ΔBIC > ``min_delta_bic``; stop when consistent or when nothing gains enough;
5. verdict: ``consistent`` when the baseline already explains the recording, ``mismatch``
   otherwise (``final`` then shows how far the chosen effects bring it);
6. for recordings spanning several nights: leave-one-night-out cross-validation of the
   baseline and of baseline + chosen effects (:func:`cross_validate`): every night is
   predicted by the model fitted to the other nights (free parameters and effect
   parameters refitted without it). The effects themselves are chosen on all the data
   (the selection is not cross-validated; the report says so).

:func:`diagnose_recording` builds the problem from files (HDF5 lightcurve, or CSV + scenario).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from .baseline import bic_gain, fit_baseline, fit_terms
from .candidates import params_to_json, score_candidates
from .residuals import consistency, find_segments

__all__ = ["Diagnosis", "diagnose", "cross_validate", "diagnose_recording", "TIMING_EFFECTS",
           "load_model_scenario", "diagnose_css_recording"]

TIMING_EFFECTS = ("light_time", "clock_offset", "exposure_smearing")


@dataclass
class Diagnosis:
    """Everything :func:`~.report.write_report` needs."""

    problem: object
    verdict: str
    baseline_fit: object
    baseline_check: dict
    segments: list
    candidates: list
    chosen: list
    final_fit: object
    final_check: dict
    cross_validation: dict | None = None
    notes: list = field(default_factory=list)

    def summary(self) -> dict:
        """The ``diagnosis.json`` content (schema in :mod:`.report`)."""
        from .report import diagnosis_json

        return diagnosis_json(self)


def _rms(problem, pred):
    d = problem.y - pred
    d = d[np.isfinite(d)]
    return float(np.sqrt(np.mean(d * d))) if d.size else float("nan")


def _starts_from(c):
    eff, params = c["_fit"].terms[0]
    return eff, params


def diagnose(problem, *, min_delta_bic: float = 10.0, max_effects: int = 2, pair_candidates: int = 3,
             cross_validation: bool | None = None, skip_reasons=None, seed: int = 0,
             max_nfev: int = 60, progress=None) -> Diagnosis:
    """Run the diagnosis of ``problem`` (module docstring). ``progress``: callable(str) or None."""
    say = progress or (lambda s: None)
    notes = []
    say("fitting the baseline")
    base = fit_baseline(problem)
    chk0 = consistency(base.z, problem.t, base.n_params)
    segs = find_segments(problem, base.z)
    say(f"baseline chi2/dof {chk0['chi2_dof']:.3g}; scoring candidates")
    cands = score_candidates(problem, base, seed=seed, max_nfev=max_nfev, skip_reasons=skip_reasons)
    chosen, final = [], base
    chk = chk0
    if not chk0["consistent"]:
        top = [c for c in cands if c.get("applicable") and c.get("delta_bic", -np.inf) > min_delta_bic]
        if top:
            chosen = [top[0]["name"]]
            final = top[0]["_fit"]
            chk = consistency(final.z, problem.t, final.n_params)
            if not chk["consistent"] and max_effects >= 2 and len(top) > 1:
                say(f"chose {chosen[0]}; trying pairs")
                e1, p1 = _starts_from(top[0])
                best_pair = None
                for c in top[1:1 + pair_candidates]:
                    e2, p2 = _starts_from(c)
                    try:
                        f2 = fit_terms(problem, [e1, e2], [[p1, p2]], theta0=final.theta,
                                       max_nfev=max_nfev, fixed_effect_params=[
                                           {k: v for k, v in p1.items() if k in _fixed_names(e1)},
                                           {k: v for k, v in p2.items() if k in _fixed_names(e2)}])
                    except Exception as exc:  # pragma: no cover - defensive
                        notes.append(f"joint fit with {c['name']} failed: {exc}")
                        continue
                    gain = bic_gain(final.chi2, f2.chi2, problem.n, f2.n_effect_params - final.n_effect_params)
                    if gain > min_delta_bic and (best_pair is None or f2.chi2 < best_pair[1].chi2):
                        best_pair = (c["name"], f2, gain)
                if best_pair is not None:
                    chosen.append(best_pair[0])
                    final = best_pair[1]
                    chk = consistency(final.z, problem.t, final.n_params)
    verdict = "consistent" if chk0["consistent"] else "mismatch"
    d = Diagnosis(problem=problem, verdict=verdict, baseline_fit=base, baseline_check=chk0,
                  segments=segs, candidates=cands, chosen=chosen, final_fit=final, final_check=chk,
                  notes=notes)
    if cross_validation is None:
        cross_validation = problem.night is not None and np.unique(
            np.asarray(problem.night)[problem.epoch_index]).size >= 3
    if cross_validation and problem.night is not None:
        say("leave-one-night-out cross-validation")
        d.cross_validation = cross_validate(problem, final, max_nfev=max_nfev, progress=say)
    return d


def _fixed_names(effect):
    from .baseline import GRID_PARAMS

    return {s.name for s in effect.params if s.integer or s.name in GRID_PARAMS}


def _pearson(a, b):
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    if a.size < 2:
        return float("nan")
    da, db = a - a.mean(), b - b.mean()
    den = np.sqrt(np.sum(da * da) * np.sum(db * db))
    return float(np.sum(da * db) / den) if den > 0 else float("nan")


def cross_validate(problem, final_fit, *, max_nfev: int = 60, progress=None) -> dict:
    """Leave-one-night-out predictions of the baseline and of baseline + chosen effects.

    For each night: the free baseline parameters (and the chosen effects' continuous
    parameters) are refitted on the other nights, starting from the all-data values, and the
    held-out night is predicted. Returns RMS (same unit as the data) and Pearson R of the
    out-of-sample predictions, before (baseline) and after (with the chosen effects), plus
    the in-sample values and the number of folds.
    """
    say = progress or (lambda s: None)
    night = np.asarray(problem.night)[problem.epoch_index]
    nights = np.unique(night)
    pred_b = np.full(problem.n, np.nan)
    pred_a = np.full(problem.n, np.nan)
    terms = final_fit.terms
    effects = [e for e, _ in terms]
    starts = [[dict(p) for _, p in terms]]
    fixed = [{k: v for k, v in p.items() if k in _fixed_names(e)} for e, p in terms]
    base_theta = problem.x0()
    for i, nt in enumerate(nights):
        test = night == nt
        train = problem.subset(~test)
        held = problem.subset(test)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if problem.n_free:
                fb = fit_terms(train, [], None, theta0=base_theta, max_nfev=max_nfev)
                th_b = fb.theta
            else:
                th_b = None
            pred_b[test] = held.predict(th_b)
            if effects:
                fa = fit_terms(train, effects, starts, theta0=final_fit.theta if problem.n_free else None,
                               max_nfev=max_nfev, fixed_effect_params=fixed)
                pred_a[test] = held.predict(fa.theta if problem.n_free else None, fa.terms)
            else:
                pred_a[test] = pred_b[test]
        if (i + 1) % 10 == 0:
            say(f"  fold {i + 1}/{nights.size}")
    y = problem.y

    def rms(p):
        d = y - p
        d = d[np.isfinite(d)]
        return float(np.sqrt(np.mean(d * d)))

    return {"method": "leave-one-night-out", "n_folds": int(nights.size),
            "effects": [e.name for e in effects],
            "rms_mag_before": rms(pred_b), "rms_mag_after": rms(pred_a),
            "r_before": _pearson(y, pred_b), "r_after": _pearson(y, pred_a),
            "n_nonfinite_after": int(np.sum(~np.isfinite(pred_a))),
            "selection_cross_validated": False}


# ----------------------------------------------------------------------------------------
# from files
# ----------------------------------------------------------------------------------------
def load_model_scenario(path):
    """Load a scenario TOML for diagnosis: the scenario with its ``[effects]`` switched off
    (the model whose missing physics is being looked for) and the ``[diagnosis]`` table, if
    any (keys ``free`` (list of words, see :func:`~.problem.parse_free`), ``exclude`` (effect
    names not to propose), ``max_effects`` (1 or 2), ``min_delta_bic`` (> 0)). Returns
    ``(scenario, options)``."""
    from pathlib import Path

    from ..io.tomlio import Section, load_toml
    from ..studies.scenario import parse_scenario

    path = Path(path)
    doc, text = load_toml(path, with_text=True)
    diag = doc.pop("diagnosis", None)
    had_effects = bool(doc.pop("effects", None))
    sc = parse_scenario(doc, file=path, text=text)
    opts = {}
    if diag is not None:
        sec = Section(diag, file=path, name="diagnosis")
        free = sec.raw("free", None)
        if free is not None:
            if not isinstance(free, list) or not all(isinstance(w, str) for w in free):
                from ..errors import InputError

                raise InputError("expected a list of names", file=path, field="diagnosis.free", value=free)
            opts["free"] = ",".join(free) if free else "none"
        ex = sec.raw("exclude", None)
        if ex is not None:
            from ..physics import available_effects

            if not isinstance(ex, list) or any(e not in available_effects() for e in ex):
                from ..errors import InputError

                raise InputError("expected a list of effect names", file=path, field="diagnosis.exclude",
                                 value=ex, allowed=", ".join(available_effects()))
            opts["exclude"] = list(ex)
        opts["max_effects"] = sec.int("max_effects", 2, min=1, max=2)
        opts["min_delta_bic"] = sec.float("min_delta_bic", 10.0, min=0.0, min_open=True)
        sec.check_unknown()
    opts["model_had_effects"] = had_effects
    return sc, opts


def diagnose_recording(recording, scenario=None, *, free=None, exclude=(), progress=None,
                       cross_validation=None, max_effects=None, min_delta_bic=None, seed=0):
    """Diagnose a recording file against a model.

    ``recording``: our lightcurve HDF5 (model = the file's own scenario or ``scenario``;
    attitude = the file's truth), a CSS recording (HDF5 with ``format = "lightcurve-css"``,
    detected from the file: :func:`diagnose_css_recording`) or a CSV recording (needs ``scenario``; attitude = the
    scenario's law or noise-free dynamics). ``free``: comma-separated words
    (:func:`~.problem.parse_free`); default ``none`` for files with a truth attitude,
    ``reflection`` for CSV recordings. Returns a :class:`Diagnosis`.
    """
    from pathlib import Path

    from ..errors import InputError
    from ..studies.scenario import parse_scenario
    from .problem import magnitude_problem, parse_free

    recording = Path(recording)
    from .css_recording import is_css_recording

    if is_css_recording(recording):
        return diagnose_css_recording(recording, scenario, free=free, exclude=exclude,
                                      progress=progress, max_effects=max_effects,
                                      min_delta_bic=min_delta_bic, seed=seed)
    opts = {}
    sc = None
    if scenario is not None:
        sc, opts = load_model_scenario(scenario)
    if recording.suffix.lower() in (".h5", ".hdf5"):
        from ..io.lightcurve_h5 import read_lightcurve

        lc = read_lightcurve(recording)
        if sc is None:
            if not lc.scenario_toml:
                raise InputError("the file has no embedded scenario: give --scenario", file=recording)
            from ..io.tomlio import loads_toml

            doc = loads_toml(lc.scenario_toml, file=f"{recording}:scenario")
            doc.pop("effects", None)
            doc.pop("diagnosis", None)
            sc = parse_scenario(doc, file=str(recording), embedded=True)
        default_free = "none"
        q = lc.truth_q
        omega = lc.truth_omega_rad_s
        if q is None:
            from ..studies.evaluate import model_attitude

            q = model_attitude(sc, lc)
            omega = None
    else:
        if sc is None:
            raise InputError("a CSV recording needs --scenario MODEL.toml (shape, attitude, sites)",
                             file=recording)
        from ..io.recording import read_recording
        from ..studies.evaluate import model_attitude

        # rows in the Earth's full shadow are kept (counted, warned) for shadow/clock effects
        lc = read_recording(recording, sc, unlit="keep")
        q = model_attitude(sc, lc)
        omega = None
        default_free = "reflection"
    words = parse_free(free if free is not None else opts.get("free", default_free), sc.shape)
    skip = {}
    if omega is None:
        for name in TIMING_EFFECTS:
            skip[name] = ("not applicable: evaluating the model at shifted times needs the body "
                          "rate and the object's velocity, unknown for this recording")
    for name in list(exclude) + list(opts.get("exclude", [])):
        skip[name] = "excluded by the user"
    prob = magnitude_problem(lc, sc.shape, q=q, omega=omega, sun_mag=sc.measurement.sun_mag,
                             ignore_eclipse=sc.measurement.ignore_eclipse, free=words,
                             label=recording.name)
    if sc.measurement.ignore_eclipse:
        # the model ignores the eclipse: umbra epochs are modelled as sunlit; the penumbra
        # effect then means "switch the partial solar disc (and the umbra) on"
        prob.ctx = prob.ctx.with_state(ignore_eclipse=True)
    d = diagnose(prob, progress=progress, cross_validation=cross_validation, skip_reasons=skip,
                 max_effects=max_effects or opts.get("max_effects", 2),
                 min_delta_bic=min_delta_bic or opts.get("min_delta_bic", 10.0), seed=seed)
    d.notes.append(f"free baseline parameters: {', '.join(p.name for p in prob.free) or 'none'}")
    if opts.get("model_had_effects"):
        d.notes.append("the scenario's [effects] table was switched off for the model")
    return d


def diagnose_css_recording(recording, configuration=None, *, free=None, exclude=(), progress=None,
                           max_effects=None, min_delta_bic=None, seed=0, max_epochs=400):
    """Diagnose a CSS recording (:mod:`.css_recording`) against the sensors' direct-Sun model.

    ``configuration``: optional CSS configuration TOML (the model's nominal sensors; the
    file's are used otherwise). The baseline has no free parameters (``free`` must be None
    or ``none``); the ``css_*`` effects are the candidates. No cross-validation (one pass).
    """
    from ..errors import InputError
    from .css_recording import css_recording_problem

    if free not in (None, "none"):
        raise InputError("a CSS baseline has no free parameters", field="--free", value=free,
                         allowed="none")
    prob, notes = css_recording_problem(recording, configuration=configuration,
                                        max_epochs=max_epochs)
    skip = {name: "excluded by the user" for name in exclude}
    d = diagnose(prob, progress=progress, cross_validation=False, skip_reasons=skip,
                 max_effects=max_effects or 2, min_delta_bic=min_delta_bic or 10.0, seed=seed)
    d.notes.extend(notes)
    d.notes.append("model: nominal sensors, direct Sun only (no albedo, nominal scale factors "
                   "and normals), attitude and orbit from the recording")
    return d
