"""Diagnosis outputs: ``DIR/diagnosis.json`` and a self-contained ``DIR/report.html``.

``diagnosis.json`` (``format_version`` 2; magnitudes for lightcurves, output units for CSS)::

    {
      "format": "lightcurve-diagnosis", "format_version": 2,
      "recording", "kind": "magnitude" | "css", "n", "epoch_utc",
      "verdict": "consistent" | "mismatch", "verdict_line": str, "explanation": str,
      "baseline": {"chi2_dof", "rms", "chi2_dof_band", "ljung_box_p", "runs_p", "consistent",
                   "tighter_than_noise", "free_params": {name: {value, sd, unit}}},
      "final":    {... the same for the baseline + the named effects ...},
      "cross_validation": {"possible", "reason", "selection": {grouping, method, n_groups,
                           n_folds, fold_sizes}, "gain_statistic",
                           "schemes": [{grouping, method, n_groups, n_folds, possible,
                                        "baseline": {rms, chi2_per_n, r}, "final": {...},
                                        "gain"}]},
      "selection": {"criterion", "min_gain", "max_effects"},
      "candidates": [{"name", "kind": "effect" | "surface", "description", "applicable",
                      "reason", "signature_r",
                      "steps": [{"step", "in_sample": {chi2_dof, rms, delta_chi2, delta_bic},
                                 "held_out": {chi2_per_n, rms, r, gain, folds_improved,
                                              n_folds},
                                 "identified", "params": {label: {value, sd, status}},
                                 "decision"}]}],
      "chosen": [names], "unidentified": [{"name", "step", "gain", "reasons"}],
      "model": {"channels", "sites", "free_params": {name: value},
                "effects": [{"name", "params": {p: value | {channel: value}},
                             "options", "held"}]},      (input of ``diagnose --apply``)
      "segments": [...], "timings_s": {...}, "notes": [str]
    }

The HTML page (UTC time axes, a one-line verdict at the top, figures sized for a screen and
only drawn when they have something to show) embeds its figures as base64 PNGs (opens
offline).
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write_text

__all__ = ["diagnosis_json", "explanation", "verdict_line", "verdict_level", "write_report",
           "fmt_value", "model_json", "candidates_table"]


def _f(x):
    if x is None:
        return None
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def fmt_value(value, sd=None, unit="", identified=True) -> str:
    """``value ± sd unit`` rounded to the sd's two significant digits; "(unidentified)" when
    the value is not identified or its sd is not smaller than |value| + the unit's scale."""
    unit = "" if unit in ("1", None) else f" {unit}"
    if value is None:
        return "–"
    v = float(value)
    if sd is None or not math.isfinite(sd) or sd <= 0:
        txt = f"{v:.3g}{unit}"
        return txt + ("" if identified else " (unidentified)")
    dec = max(0, 1 - int(math.floor(math.log10(sd))))
    txt = f"{v:.{dec}f} ± {sd:.{dec}f}{unit}"
    return txt if identified else txt + " (unidentified)"


def _check_json(chk, fit, problem):
    return {"chi2_dof": _f(chk["chi2_dof"]), "rms": _f(fit.rms(problem.y)),
            "chi2_dof_band": [_f(v) for v in chk["chi2_dof_band"]],
            "ljung_box_p": _f(chk["whiteness"]["ljung_box"]["p_value"]),
            "runs_p": _f(chk["whiteness"]["runs"]["p_value"]), "consistent": chk["consistent"],
            "tighter_than_noise": chk.get("tighter_than_noise", False)}


def _free_json(fit, problem):
    out = {}
    for i, p in enumerate(problem.free):
        sd = _f(fit.sd[i]) if fit.sd is not None and i < len(fit.sd) else None
        out[p.name] = {"value": _f(fit.theta[i]) if fit.theta.size > i else _f(p.x0), "sd": sd,
                       "unit": p.unit, "scenario_value": _f(p.x0)}
    return out


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return [_f(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return _f(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    return v


def model_json(model) -> dict:
    """The fitted model in the form ``diagnose --apply`` reads (module docstring)."""
    prob = model.problem
    fit = model.fit
    out = {"channels": prob.channel_names, "sites": list(prob.site_names),
           "free_params": {p.name: _f(v) for p, v in zip(prob.free, fit.theta)}, "effects": []}
    for (eff, params) in fit.terms:
        pj = {}
        for s in eff.params:
            v = params[s.name]
            if s.per in ("site", "camera") and np.ndim(v):
                names = prob.site_names if s.per == "site" else prob.channel_names
                pj[s.name] = {n: _f(x) for n, x in zip(names, np.asarray(v))}
            else:
                pj[s.name] = _jsonable(v)
        out["effects"].append({"name": eff.name, "params": pj, "options": _jsonable(dict(eff.opts)),
                               "held": sorted(set(eff.hold) | set(getattr(eff, "diagnosis_hold", {})))})
    return out


def _step_json(r):
    out = {"step": r.get("step"), "applicable": r.get("applicable", False)}
    if not r.get("applicable"):
        out["reason"] = r.get("reason", "")
        return out
    out["in_sample"] = {k: _f(v) for k, v in r["in_sample"].items()}
    if "held_out" in r:
        h = r["held_out"]
        out["held_out"] = {k: _f(h[k]) for k in ("chi2_per_n", "rms", "r", "gain")}
        out["held_out"]["folds_improved"] = int(h.get("folds_improved", 0))
        out["held_out"]["n_folds"] = int(h.get("n_folds", 0))
        out["held_out"]["fold_params"] = _jsonable(h.get("fold_params", []))
    out["gain"] = _f(r.get("gain"))
    out["identified"] = bool(r.get("identified"))
    ident = r.get("identification", {})
    out["params"] = {k: {kk: (_jsonable(vv)) for kk, vv in v.items() if kk != "ok"}
                     for k, v in ident.get("params", {}).items()}
    out["decision"] = r.get("decision", "")
    return out


def _candidates_json(d):
    out = []
    for c in d.candidates:
        cc = {"name": c["name"], "kind": c.get("kind", "effect"),
              "description": c.get("description", ""), "applicable": bool(c.get("applicable")),
              "reason": c.get("reason", ""), "signature_r": _f(c.get("signature_r"))}
        if c.get("_dropped"):
            cc["held_degenerate"] = {n: why for n, why in c["_dropped"]}
        cc["steps"] = [_step_json(r) for r in c.get("steps", [])]
        out.append(cc)
    return out


def _best_step1(d):
    """Step-1 records of applicable candidates, best held-out gain first."""
    recs = [r for s in d.steps[:1] for r in s["records"] if r.get("applicable")]
    return sorted(recs, key=lambda r: -(r.get("gain") if np.isfinite(r.get("gain", np.nan)) else -1e300))


def verdict_line(d) -> str:
    """One line: the answer."""
    if d.verdict == "consistent":
        b = d.baseline_check
        extra = " (tighter than the stated noise)" if b.get("tighter_than_noise") else ""
        return (f"Consistent: the model explains the recording within its noise "
                f"(χ²/dof {b['chi2_dof']:.2f}{extra}); no missing physics needed.")
    if d.chosen:
        return (f"Mismatch: missing physics found — {', '.join(d.chosen)} — and it improves "
                f"the fit on held-out data." if d.folds is not None else
                f"Mismatch: missing physics found — {', '.join(d.chosen)} (no held-out check "
                "possible).")
    if d.unidentified:
        return ("Mismatch: no effect can be named; "
                f"{', '.join(u['name'] for u in d.unidentified)} fit(s), but unidentifiable with "
                "these data.")
    return "Mismatch: none of the known effects explains it on held-out data."


def verdict_level(d) -> str:
    """``ok`` (consistent), ``warn`` (mismatch, missing physics named) or ``fail`` (mismatch,
    nothing can be named) — the colours of :func:`lightcurve.report.style.verdict_html`."""
    if d.verdict == "consistent":
        return "ok"
    return "warn" if d.chosen else "fail"


def candidates_table(js) -> list:
    """One flat row per candidate: the numbers of its first evaluated step (in-sample and
    held out side by side), whether it is identified, and the decision."""
    rows = []
    for c in js["candidates"]:
        r = {"name": c["name"], "kind": c["kind"], "applicable": c["applicable"],
             "reason": c.get("reason", "")}
        st = next((s for s in c["steps"] if s.get("applicable")), None)
        if st is not None:
            r.update({"step": st["step"], "chi2_dof_in_sample": st["in_sample"].get("chi2_dof"),
                      "rms_in_sample": st["in_sample"].get("rms"),
                      "delta_bic_in_sample": st["in_sample"].get("delta_bic"),
                      "rms_held_out": st.get("held_out", {}).get("rms"),
                      "chi2_per_n_held_out": st.get("held_out", {}).get("chi2_per_n"),
                      "gain_held_out": st.get("held_out", {}).get("gain"),
                      "identified": st["identified"], "decision": st.get("decision", "")})
        rows.append(r)
    return rows


def _param_phrases(rec, units):
    out = []
    for k, v in rec.get("identification", {}).get("params", {}).items():
        if str(v.get("status", "")).startswith("held") or v.get("status") == "no data" \
                or v.get("value") is None:
            continue
        unit = units.get(k.split("[", 1)[0], "")
        out.append(f"{k} = {fmt_value(v.get('value'), v.get('sd'), unit, v.get('ok', True))}")
    return "; ".join(out)


def _units(d, name):
    from ..physics import effect_class

    if name == "surface":
        return {p.name: p.unit for p in d.final_model.problem.free} if d.final_model else {}
    try:
        return {s.name: s.unit for s in effect_class(name).params}
    except KeyError:  # pragma: no cover
        return {}


def explanation(d) -> str:
    """One plain-language paragraph a non-expert can act on."""
    p = d.problem
    unit = "mag" if p.kind == "magnitude" else "(output units)"
    b = d.baseline_check
    lo, hi = b["chi2_dof_band"]
    if d.verdict == "consistent":
        txt = (f"The model explains the recording: the residuals have χ²/dof = {b['chi2_dof']:.2f} "
               f"(noise alone gives {lo:.2f}–{hi:.2f})")
        txt += (", tighter than the stated measurement noise — the uncertainties given with the "
                "data are probably too large — so nothing is missing."
                if b.get("tighter_than_noise") else " and no pattern in time, so no missing "
                "physics is needed. Use the model as it is.")
        return txt
    txt = (f"The model does not match the recording: the residuals are {math.sqrt(max(b['chi2_dof'], 0)):.1f} "
           f"times the stated noise (χ²/dof = {b['chi2_dof']:.2f}; noise alone gives {lo:.2f}–{hi:.2f})")
    sys_segs = [s for s in d.segments if s["systematic"]]
    if sys_segs:
        txt += ", and the misfit is worst in " + ", ".join(
            s["label"] if s["kind"] == "geometry" else f"{s['kind']} {s['label']}" for s in sys_segs[:3])
    txt += ". "
    if d.folds is not None:
        txt += (f"Each candidate was fitted on part of the data and judged on the rest "
                f"({d.folds.describe()}). ")
    else:
        txt += f"No held-out check was possible ({d.cv_reason}); effects were judged in-sample. "
    by = {c["name"]: c for c in d.candidates}
    recs = {r["name"]: r for s in d.steps for r in s["records"]
            if str(r.get("decision", "")).startswith("added")}
    for i, name in enumerate(d.chosen):
        c, r = by[name], recs.get(name, {})
        desc = c.get("description", name)
        head, body = (x.strip() for x in desc.split(":", 1)) if ":" in desc else (name, desc)
        label = head[0].lower() + head[1:]
        if label.replace("-", " ") != name.replace("_", " "):
            label += f" ({name})"
        txt += ("The most likely missing physics is " if i == 0 else "It also needs ") \
            + f"{label}: " + body[0].lower() + body[1:]
        ph = _param_phrases(r, _units(d, name))
        if ph:
            txt += f" Fitted: {ph}."
        if "held_out" in r:
            txt += f" On held-out data it lowers the RMS to {r['held_out']['rms']:.3f} {unit}."
        txt += " "
    for u in d.unidentified:
        if u["name"] in d.chosen:
            continue
        txt += (f"{u['name']} would also improve the fit, but its parameters are not identified by "
                f"these data ({'; '.join(u['reasons'][:2])}), so it is not named. ")
    if not d.chosen:
        txt += ("None of the known effects improves the prediction of held-out data enough to be "
                "named; the cause is something the effect library does not model, or the data "
                "cannot tell. Check the model's inputs (shape, attitude, calibration) first.")
        return txt.strip()
    f = d.final_check
    txt += (f"With {' and '.join(d.chosen)}, χ²/dof falls from {b['chi2_dof']:.2f} to {f['chi2_dof']:.2f} "
            f"and the RMS from {d.baseline_fit.rms(p.y):.3f} to {d.final_fit.rms(d.final_model.problem.y):.3f} {unit}")
    txt += ("; the residuals are now consistent with noise. Add these effects to the model."
            if f["consistent"] else "; the residuals are still wider than the noise, so something "
            "else is missing too. Add the named effects, then look at what remains.")
    return txt


def diagnosis_json(d) -> dict:
    """The JSON-ready dict of a :class:`~.diagnose.Diagnosis` (module docstring)."""
    p = d.problem
    base = _check_json(d.baseline_check, d.baseline_fit, p)
    base["free_params"] = _free_json(d.baseline_fit, p)
    fp = d.final_model.problem if d.final_model is not None else p
    final = _check_json(d.final_check, d.final_fit, fp)
    final["free_params"] = _free_json(d.final_fit, fp)
    out = {"format": "lightcurve-diagnosis", "format_version": 2, "recording": p.label,
           "kind": p.kind, "n": p.n, "epoch_utc": getattr(p.ctx, "epoch_utc", None),
           "verdict": d.verdict, "verdict_line": verdict_line(d), "explanation": explanation(d),
           "baseline": base, "final": final,
           "cross_validation": _jsonable(d.cross_validation or {"possible": False,
                                                                "reason": d.cv_reason}),
           "selection": {"criterion": ("held-out gain G > min_gain and parameters identified"
                                       if d.folds is not None else
                                       "in-sample ΔBIC > min_gain and parameters identified "
                                       "(no cross-validation possible)")},
           "candidates": _candidates_json(d), "chosen": list(d.chosen),
           "unidentified": _jsonable(d.unidentified),
           "model": model_json(d.final_model) if d.final_model is not None else None,
           "segments": _jsonable(d.segments), "timings_s": _jsonable(d.timings),
           "notes": list(d.notes)}
    return out


# ----------------------------------------------------------------------------------------
def _png(fig) -> str:
    from ..report.html import figure_to_data_uri

    return figure_to_data_uri(fig).split(",", 1)[1]


def _figures(d):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..report.style import figsize, utc_axis, utc_times

    p = d.problem
    figs = []
    unit = "mag" if p.kind == "magnitude" else "output"
    epoch = getattr(p.ctx, "epoch_utc", None)
    x = utc_times(epoch, p.t) if epoch else p.t
    fp = d.final_model.problem if d.final_model is not None else p
    rb = p.y - d.baseline_fit.pred
    rf = fp.y - d.final_fit.pred
    lim = np.nanpercentile(np.abs(np.r_[rb, rf][np.isfinite(np.r_[rb, rf])]), 99.5) * 1.1 \
        if np.any(np.isfinite(rb)) else 1.0
    fig, axes = plt.subplots(2, 1, figsize=figsize(10, 5), sharex=True, sharey=True, dpi=100)
    names = p.channel_names if p.kind == "magnitude" else p.site_names
    chan = p.channel if p.kind == "magnitude" else p.site
    for ax, r, title in ((axes[0], rb, "model as given"),
                         (axes[1], rf, "with " + (" + ".join(d.chosen) or "nothing added"))):
        for k, s in enumerate(names):
            m = chan == k
            if np.any(m):
                ax.plot(x[m], r[m], ".", ms=3, label=s if len(names) <= 8 else None)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"measured − model, {unit}")
        ax.set_title(title, fontsize=9)
        ax.set_ylim(-lim, lim)
    if epoch:
        utc_axis(axes[0], label=None, offset=False)
        utc_axis(axes[1])
    else:
        axes[1].set_xlabel("t, s since the start")
    if 1 < len(names) <= 8:
        axes[0].legend(fontsize=7, ncol=min(len(names), 4))
    fig.tight_layout()
    figs.append(("Residuals against time, before and after", _png(fig)))
    # residuals against each named effect's signature (only when it varies)
    from .candidates import signature_matrix

    ctx = p.base_context(d.baseline_fit.theta)
    for name in d.chosen:
        c = next(c for c in d.candidates if c["name"] == name)
        if c.get("kind") != "effect":
            continue
        try:
            S = signature_matrix(c["_eff"], p, ctx).sum(axis=1)
        except Exception:  # pragma: no cover - plotting must not fail the run
            continue
        if not np.any(np.isfinite(S)) or np.nanstd(S) == 0:
            continue
        fig, ax = plt.subplots(1, 2, figsize=figsize(10, 3.4), sharey=True, dpi=100)
        ax[0].plot(S, rb, ".", ms=3)
        ax[0].set_title("model as given", fontsize=9)
        ax[1].plot(S, rf, ".", ms=3, color="C2")
        ax[1].set_title(f"with {' + '.join(d.chosen)}", fontsize=9)
        for a in ax:
            a.axhline(0, color="k", lw=0.5)
            a.set_xlabel(f"{name} signature")
        ax[0].set_ylabel(f"measured − model, {unit}")
        fig.tight_layout()
        figs.append((f"Residuals against the signature of {name}", _png(fig)))
    # held-out gain of every candidate at the first step (when there is one)
    recs = [r for r in _best_step1(d) if np.isfinite(r.get("gain", np.nan))]
    if recs and d.folds is not None:
        fig, ax = plt.subplots(figsize=figsize(10, 0.35 * len(recs) + 1.2), dpi=100)
        g = np.array([r["gain"] for r in recs])
        # green: named in the final model (at this step, a later one or in a joint pair), so
        # the colours agree with the verdict; orange: fits but unidentifiable; grey: the rest
        chosen = set(d.chosen)
        col = ["C2" if (r["name"] in chosen or str(r.get("decision", "")).startswith("added"))
               else ("C1" if not r.get("identified") else "0.6") for r in recs]
        yy = np.arange(len(recs))[::-1]
        ax.barh(yy, np.sign(g) * np.log10(1 + np.abs(g)), color=col)
        ax.set_yticks(yy, [r["name"] for r in recs])
        ax.axvline(np.log10(11.0), color="k", lw=0.6, ls="--")
        ax.set_xlabel("held-out gain G (sign · log10(1 + |G|)); dashed: G = 10")
        ax.set_title("first step: green named in the final model, orange unidentifiable, "
                     "grey not enough", fontsize=9)
        fig.tight_layout()
        figs.append(("Held-out gain of each candidate (first step)", _png(fig)))
    return figs


def _pfmt(pv):
    if pv is None:
        return "–"
    return "< 1e-16" if pv < 1e-16 else f"{pv:.2g}"


def _cand_rows(js, d):
    rows = []
    for c in js["candidates"]:
        if not c["applicable"] or not c["steps"]:
            rows.append(f"<tr><td>{html.escape(c['name'])}</td><td colspan=8>"
                        f"{html.escape(c.get('reason') or 'not evaluated')}</td></tr>")
            continue
        for s in c["steps"]:
            if not s.get("applicable"):
                rows.append(f"<tr><td>{html.escape(c['name'])} (step {s['step']})</td><td colspan=8>"
                            f"{html.escape(s.get('reason', ''))}</td></tr>")
                continue
            ins, ho = s["in_sample"], s.get("held_out", {})
            units = _units(d, c["name"])
            par = "; ".join(f"{k} = {fmt_value(v.get('value') if not isinstance(v.get('value'), list) else None, v.get('sd'), units.get(k.split('[', 1)[0], ''), v.get('status') in ('identified', 'no data'))}"
                            for k, v in s["params"].items()
                            if not str(v.get("status", "")).startswith("held") and v.get("status") != "no data"
                            and v.get("value") is not None)
            idt = "yes" if s["identified"] else "no"

            def g(x, f="{:.3g}"):
                return "–" if x is None else f.format(x)

            rows.append(
                f"<tr><td>{html.escape(c['name'])}{'' if s['step'] == 1 else ' (step ' + str(s['step']) + ')'}</td>"
                f"<td>{g(ins.get('chi2_dof'))}</td><td>{g(ins.get('rms'), '{:.3f}')}</td>"
                f"<td>{g(ins.get('delta_bic'), '{:.1f}')}</td>"
                f"<td>{g(ho.get('rms'), '{:.3f}')}</td><td>{g(ho.get('gain'), '{:.1f}')}</td>"
                f"<td>{ho.get('folds_improved', '–')}/{ho.get('n_folds', '–')}</td><td>{idt}</td>"
                f"<td>{html.escape(s.get('decision', ''))}</td></tr>"
                f"<tr class=p><td></td><td colspan=8>{html.escape(par)}</td></tr>")
    return "".join(rows)


def write_report(d, out_dir) -> tuple[Path, Path]:
    """Write ``diagnosis.json`` and ``report.html`` into ``out_dir`` (atomic writes)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    js = diagnosis_json(d)
    jpath = out / "diagnosis.json"
    atomic_write_text(jpath, json.dumps(js, indent=1, allow_nan=False, default=_json_default) + "\n")
    figs = _figures(d)
    unit = "mag" if d.problem.kind == "magnitude" else "output units"
    cv = js["cross_validation"]
    cvrows = ""
    for sch in cv.get("schemes", []):
        if not sch.get("possible"):
            cvrows += (f"<tr><td>{html.escape(sch['grouping'])}</td><td colspan=6>"
                       f"{html.escape(sch.get('reason', ''))}</td></tr>")
            continue
        b, f = sch["baseline"], sch["final"]
        cvrows += (f"<tr><td>{html.escape(sch['method'])} ({sch['n_groups']} in {sch['n_folds']} folds)</td>"
                   f"<td>{b['rms']:.3f}</td><td>{f['rms']:.3f}</td><td>{b['r']:.3f}</td>"
                   f"<td>{f['r']:.3f}</td><td>{(sch['gain'] or 0):.1f}</td></tr>")
    if not cv.get("possible"):
        cvh = f"<p><b>No cross-validation:</b> {html.escape(str(cv.get('reason')))}.</p>"
    else:
        cvh = ("<table><tr><th>held out</th><th>RMS as given</th><th>RMS final</th><th>R as given</th>"
               f"<th>R final</th><th>gain G</th></tr>{cvrows}</table>"
               f"<p class=s>RMS in {unit}; G = n ln(χ²<sub>held</sub>(before)/χ²<sub>held</sub>(after)).</p>")
    segs = "".join(
        f"<tr><td>{html.escape(s['kind'])}</td><td>{html.escape(s['label'])}</td><td>{s['n']}</td>"
        f"<td>{s['mean_z']:.2f}</td><td>{s['chi2_per_n']:.2f}</td><td>{_pfmt(s['p_value'])}</td>"
        f"<td>{'yes' if s['systematic'] else ''}</td></tr>" for s in js["segments"][:15])
    scale = js["segments"][0].get("scale", 1.0) if js["segments"] else 1.0
    tim = " · ".join(f"{k.replace('_s', '')} {v:.1f} s" for k, v in js["timings_s"].items() if v is not None)
    from ..report.style import page_html

    b, f = js["baseline"], js["final"]
    css = ("<style>tr.p td{border-top:none;color:#555;font-size:0.9em;text-align:left}"
           ".s{color:#555;font-size:0.85em}</style>")
    body = f"""{css}
<p>Recording: {html.escape(js['recording'])} ({js['n']} measurements).</p>
<p>{html.escape(js['explanation'])}</p>
<table><tr><th></th><th>χ²/dof</th><th>RMS, {unit}</th><th>consistent with noise</th></tr>
<tr><td>model as given</td><td>{b['chi2_dof']:.3g}</td><td>{b['rms']:.4g}</td><td>{'yes' if b['consistent'] else 'no'}</td></tr>
<tr><td>with {html.escape(' + '.join(js['chosen']) or 'nothing added')}</td><td>{f['chi2_dof']:.3g}</td><td>{f['rms']:.4g}</td><td>{'yes' if f['consistent'] else 'no'}</td></tr></table>
<p class=s>χ²/dof expected for noise alone: {b['chi2_dof_band'][0]:.3g}–{b['chi2_dof_band'][1]:.3g}.</p>
<h2>Held-out check</h2>
{cvh}
{''.join(f'<h2>{html.escape(t)}</h2><img alt="{html.escape(t)}" src="data:image/png;base64,{im}">' for t, im in figs)}
<h2>Candidates</h2>
<p class=s>Each candidate fitted jointly with the model so far: in-sample (all data) and held out
(fold by fold). An effect is named when its held-out gain G exceeds 10 and its parameters are
identified (not at a bound, posterior well inside the prior, detected, |correlation| &lt; 0.999).</p>
<table><tr><th>candidate</th><th>χ²/dof in</th><th>RMS in</th><th>ΔBIC in</th><th>RMS held out</th>
<th>G held out</th><th>folds better</th><th>identified</th><th>decision</th></tr>
{_cand_rows(js, d)}</table>
<h2>Where the residuals are systematic</h2>
<p class=s>{'Tested against the residual scale of the whole recording (×' + format(scale, '.2g') + ' the stated noise): "worse than elsewhere".' if scale > 1 else 'Tested against the stated noise.'}</p>
<table><tr><th>kind</th><th>segment</th><th>n</th><th>mean z</th><th>χ²/n</th><th>p</th><th>systematic</th></tr>
{segs}</table>
<h2>Notes</h2><ul>{''.join(f'<li>{html.escape(n)}</li>' for n in js['notes'])}</ul>
<p class=s>Run time: {html.escape(tim)}.</p>
"""
    page = page_html(f"Model-mismatch diagnosis: {js['recording']}", (verdict_level(d), js["verdict_line"]),
                     body)
    hpath = out / "report.html"
    atomic_write_text(hpath, page)
    return jpath, hpath


def _json_default(o):
    if isinstance(o, (np.floating,)):
        return _f(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.ndarray):
        return [_json_default(x) for x in o.tolist()]
    raise TypeError(f"not JSON serialisable: {type(o)}")
