"""Diagnosis outputs: ``DIR/diagnosis.json`` and a self-contained ``DIR/report.html``.

``diagnosis.json`` schema (units: magnitudes for lightcurves, CSS output units for CSS)::

    {
      "format": "lightcurve-diagnosis", "format_version": 1,
      "recording": str, "kind": "magnitude" | "css", "n": int,
      "verdict": "consistent" | "mismatch",
      "baseline": {"chi2_dof", "rms_mag", "chi2_dof_band": [lo, hi], "ljung_box_p",
                   "runs_p", "consistent", "free_params": {name: {value, sd}}},
      "segments": [{"kind": "site"|"sensor"|"time"|"geometry", "label", "n", "t_start_s",
                    "t_end_s", "mean_z", "chi2_per_n", "p_value", "systematic"}],
      "candidates": [{"rank", "name", "applicable", "reason", "delta_bic", "delta_chi2",
                      "signature_r", "chi2_dof", "rms_mag", "n_params",
                      "params": {param: {"value", "sd", "unit"} |
                                        {"unit", "per", "values": {site: {"value", "sd"}}}},
                      "description"}],
      "chosen": [names], "chosen_params": {name: params},
      "final": {"chi2_dof", "rms_mag", "consistent", "ljung_box_p", "runs_p"},
      "cross_validation": {"method", "n_folds", "effects", "rms_mag_before", "rms_mag_after",
                           "r_before", "r_after", ...}   (only for several nights),
      "explanation": str, "notes": [str]
    }

``delta_bic`` = BIC(baseline) − BIC(baseline + effect) (positive favours the effect).
The HTML page embeds its matplotlib figures as base64 PNGs (opens offline): standardised
residuals before/after against time, and against each chosen effect's signature.
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write_text

__all__ = ["diagnosis_json", "explanation", "write_report"]


def _f(x):
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _check_json(chk, fit, problem):
    unit = "rms_mag" if problem.kind == "magnitude" else "rms"
    return {"chi2_dof": _f(chk["chi2_dof"]), unit: _f(fit.rms(problem.y)),
            "chi2_dof_band": [_f(v) for v in chk["chi2_dof_band"]],
            "ljung_box_p": _f(chk["whiteness"]["ljung_box"]["p_value"]),
            "runs_p": _f(chk["whiteness"]["runs"]["p_value"]), "consistent": chk["consistent"]}


def _free_json(fit, problem):
    out = {}
    for i, p in enumerate(problem.free):
        sd = None
        if fit.sd is not None and i < len(fit.sd):
            sd = _f(fit.sd[i])
        out[p.name] = {"value": _f(fit.theta[i]) if fit.theta.size > i else _f(p.x0), "sd": sd,
                       "unit": p.unit, "scenario_value": _f(p.x0)}
    return out


def _fmt_params(params) -> str:
    parts = []
    for k, v in params.items():
        if "values" in v:
            vals = ", ".join(f"{s} {d['value']:.3g}" + (f" ± {d['sd']:.2g}" if d.get("sd") else "")
                             for s, d in v["values"].items())
            parts.append(f"{k} = {vals} {v['unit']}")
        else:
            parts.append(f"{k} = {v['value']:.3g}" + (f" ± {v['sd']:.2g}" if v.get("sd") else "")
                         + f" {v['unit']}")
    return "; ".join(parts)


def explanation(d) -> str:
    """One plain-language paragraph from the effects' descriptions and fitted values."""
    p = d.problem
    unit = "mag" if p.kind == "magnitude" else "(output units)"
    b = d.baseline_check
    if d.verdict == "consistent":
        txt = (f"The model explains the recording: the residuals have χ²/dof = {b['chi2_dof']:.2f} "
               f"(expected {b['chi2_dof_band'][0]:.2f}–{b['chi2_dof_band'][1]:.2f} for noise alone) "
               "and show no time correlation, so no missing physics is needed.")
        best = next((c for c in d.candidates if c.get("applicable")), None)
        if best is not None:
            txt += (f" The best-scoring extra effect, {best['name']}, would change the fit by "
                    f"ΔBIC = {best['delta_bic']:.1f}, not enough to claim it.")
        return txt
    txt = (f"The model does not match the recording: χ²/dof = {b['chi2_dof']:.2f} where noise alone "
           f"would give {b['chi2_dof_band'][0]:.2f}–{b['chi2_dof_band'][1]:.2f}")
    sys_segs = [s for s in d.segments if s["systematic"]]
    if sys_segs:
        txt += ", and the misfit is concentrated in " + ", ".join(
            f"{s['label']}" if s["kind"] == "geometry" else f"{s['kind']} {s['label']}"
            for s in sys_segs[:3])
    txt += ". "
    if not d.chosen:
        txt += "None of the known effects explains it well enough (ΔBIC > 10); the cause is " \
               "something the effect library does not model."
        return txt
    by = {c["name"]: c for c in d.candidates}
    for i, name in enumerate(d.chosen):
        c = by[name]
        params = d.summary_params.get(name, c.get("params", {})) if hasattr(d, "summary_params") else c.get("params", {})
        txt += ("The most likely missing physics is " if i == 0 else "Adding ") + f"{name}: " \
            + c["description"][0].lower() + c["description"][1:]
        if params:
            txt += f" Fitted: {_fmt_params(params)}."
        txt += " "
    f = d.final_check
    txt += (f"With {' and '.join(d.chosen)} switched on, χ²/dof falls from {b['chi2_dof']:.2f} to "
            f"{f['chi2_dof']:.2f} and the RMS from {d.baseline_fit.rms(p.y):.3f} to "
            f"{d.final_fit.rms(p.y):.3f} {unit}")
    txt += (", and the residuals are consistent with noise." if f["consistent"] else
            "; the residuals are still not consistent with noise, so something else is missing too.")
    cv = d.cross_validation
    if cv:
        txt += (f" Out of sample (leave one night out, {cv['n_folds']} nights) the RMS goes from "
                f"{cv['rms_mag_before']:.3f} to {cv['rms_mag_after']:.3f} {unit} and Pearson R from "
                f"{cv['r_before']:.3f} to {cv['r_after']:.3f}.")
    return txt


def _chosen_params(d):
    out = {}
    for i, name in enumerate(d.chosen):
        if i < len(d.final_fit.terms):
            from .candidates import params_to_json

            out[name] = params_to_json(d.final_fit, d.problem, i)
    return out


def diagnosis_json(d) -> dict:
    """The JSON-ready dict of a :class:`~.diagnose.Diagnosis` (module docstring)."""
    p = d.problem
    d.summary_params = _chosen_params(d)
    unit = "rms_mag" if p.kind == "magnitude" else "rms"
    cands = []
    for c in d.candidates:
        cc = {k: v for k, v in c.items() if not k.startswith("_")}
        for k in ("delta_bic", "delta_chi2", "signature_r", "chi2_dof", unit):
            if k in cc:
                cc[k] = _f(cc[k])
        cands.append(cc)
    base = _check_json(d.baseline_check, d.baseline_fit, p)
    base["free_params"] = _free_json(d.baseline_fit, p)
    final = _check_json(d.final_check, d.final_fit, p)
    final["free_params"] = _free_json(d.final_fit, p)
    out = {"format": "lightcurve-diagnosis", "format_version": 1, "recording": p.label,
           "kind": p.kind, "n": p.n, "verdict": d.verdict, "baseline": base,
           "segments": d.segments, "candidates": cands, "chosen": list(d.chosen),
           "chosen_params": d.summary_params, "final": final}
    if d.cross_validation is not None:
        out["cross_validation"] = {k: (_f(v) if isinstance(v, float) else v)
                                   for k, v in d.cross_validation.items()}
    out["explanation"] = explanation(d)
    out["notes"] = list(d.notes)
    return out


# ----------------------------------------------------------------------------------------
def _png(fig) -> str:
    """Base64 PNG of a figure (closed afterwards); shared with the study report."""
    from ..report.html import figure_to_data_uri

    return figure_to_data_uri(fig).split(",", 1)[1]


def _figures(d):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .candidates import signature_matrix

    p = d.problem
    figs = []
    fig, axes = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    for ax, fit, title in ((axes[0], d.baseline_fit, "baseline"),
                           (axes[1], d.final_fit, "final: " + (" + ".join(d.chosen) or "baseline"))):
        for k, s in enumerate(p.site_names):
            m = p.site == k
            if np.any(m):
                ax.plot(p.t[m], fit.z[m], ".", ms=3, label=s if p.kind == "magnitude" else None)
        ax.axhline(0, color="k", lw=0.5)
        for v in (-3, 3):
            ax.axhline(v, color="0.6", lw=0.5, ls="--")
        ax.set_ylabel("z = (y − model)/σ")
        ax.set_title(title, fontsize=9)
    axes[1].set_xlabel("t, s since the epoch")
    if p.kind == "magnitude" and len(p.site_names) > 1:
        axes[0].legend(fontsize=7)
    figs.append(("Standardised residuals against time, before and after", _png(fig)))
    ctx = p.base_context(d.baseline_fit.theta)
    for name in d.chosen:
        c = next(c for c in d.candidates if c["name"] == name)
        eff = c["_fit"].terms[0][0]
        try:
            S = signature_matrix(eff, p, ctx).sum(axis=1)
        except Exception:  # pragma: no cover - plotting must not fail the run
            continue
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.2), sharey=True)
        ax[0].plot(S, d.baseline_fit.z, ".", ms=3)
        ax[0].set_title("baseline residuals", fontsize=9)
        ax[1].plot(S, d.final_fit.z, ".", ms=3, color="C2")
        ax[1].set_title("after", fontsize=9)
        for a in ax:
            a.axhline(0, color="k", lw=0.5)
            a.set_xlabel(f"{name} signature")
        ax[0].set_ylabel("z")
        figs.append((f"Residuals against the signature of {name}", _png(fig)))
    return figs


def write_report(d, out_dir) -> tuple[Path, Path]:
    """Write ``diagnosis.json`` and ``report.html`` into ``out_dir`` (atomic writes)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    js = diagnosis_json(d)
    jpath = out / "diagnosis.json"
    atomic_write_text(jpath, json.dumps(js, indent=2, allow_nan=False, default=_json_default) + "\n")
    figs = _figures(d)
    rows = []
    for c in js["candidates"]:
        if c.get("applicable"):
            rows.append(f"<tr><td>{c['rank']}</td><td>{html.escape(c['name'])}</td>"
                        f"<td>{c['delta_bic']:.1f}</td><td>{(c.get('signature_r') or 0):.2f}</td>"
                        f"<td>{(c.get('chi2_dof') or float('nan')):.3g}</td>"
                        f"<td>{html.escape(_fmt_params(c.get('params', {})))}</td></tr>")
        else:
            rows.append(f"<tr><td>–</td><td>{html.escape(c['name'])}</td><td colspan=4>"
                        f"{html.escape(c.get('reason', ''))}</td></tr>")
    segs = "".join(
        f"<tr><td>{html.escape(s['kind'])}</td><td>{html.escape(s['label'])}</td><td>{s['n']}</td>"
        f"<td>{s['mean_z']:.2f}</td><td>{s['chi2_per_n']:.2f}</td><td>{s['p_value']:.2g}</td>"
        f"<td>{'yes' if s['systematic'] else ''}</td></tr>" for s in js["segments"][:25])
    cv = js.get("cross_validation")
    cvh = ""
    if cv:
        cvh = (f"<h2>Cross-validation ({html.escape(cv['method'])}, {cv['n_folds']} folds)</h2>"
               f"<p>RMS {cv['rms_mag_before']:.3f} → {cv['rms_mag_after']:.3f}; Pearson R "
               f"{cv['r_before']:.3f} → {cv['r_after']:.3f} (effects: "
               f"{html.escape(', '.join(cv['effects']) or 'none')}; the choice of effects was made "
               "on all the data).</p>")
    unit = "rms_mag" if d.problem.kind == "magnitude" else "rms"
    page = f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>Diagnosis: {html.escape(js['recording'])}</title>
<style>body{{font-family:sans-serif;max-width:960px;margin:2em auto;line-height:1.4}}
table{{border-collapse:collapse;font-size:0.85em}}td,th{{border:1px solid #ccc;padding:2px 6px}}
.v{{font-size:1.3em;font-weight:bold}}</style></head><body>
<h1>Model-mismatch diagnosis</h1>
<p>Recording: {html.escape(js['recording'])} ({js['n']} measurements).
Verdict: <span class="v">{js['verdict']}</span>.</p>
<p>{html.escape(js['explanation'])}</p>
<p>Baseline χ²/dof {js['baseline']['chi2_dof']:.3g} (band {js['baseline']['chi2_dof_band'][0]:.3g}–{js['baseline']['chi2_dof_band'][1]:.3g}),
RMS {js['baseline'][unit]:.4g}; final χ²/dof {js['final']['chi2_dof']:.3g}, RMS {js['final'][unit]:.4g}.
Chosen: {html.escape(', '.join(js['chosen']) or 'none')}.</p>
{cvh}
{''.join(f'<h2>{html.escape(t)}</h2><img alt="{html.escape(t)}" src="data:image/png;base64,{b}">' for t, b in figs)}
<h2>Candidates (ΔBIC = BIC(baseline) − BIC(with effect))</h2>
<table><tr><th>rank</th><th>effect</th><th>ΔBIC</th><th>signature r</th><th>χ²/dof</th><th>parameters (±1σ)</th></tr>
{''.join(rows)}</table>
<h2>Where the residuals are systematic</h2>
<table><tr><th>kind</th><th>segment</th><th>n</th><th>mean z</th><th>χ²/n</th><th>p</th><th>systematic</th></tr>
{segs}</table>
<h2>Notes</h2><ul>{''.join(f'<li>{html.escape(n)}</li>' for n in js['notes'])}</ul>
</body></html>
"""
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
