"""Apply a fitted diagnosis model unchanged to new recordings: does the fit transfer?

``lightcurve diagnose NEW --apply FIT.json`` reads the ``model`` of a ``diagnosis.json``
(format version 2, :func:`~.report.model_json`: the fitted free baseline parameters — a
surface refit, zero points — and the named effects with their fitted parameters) and
predicts the new recording with

* the model as given (the scenario, nothing fitted: the reference);
* every fitted component alone (the surface refit; each effect) and all of them together;

nothing is refitted. For each prediction the report gives χ²/dof, RMS, Pearson R and the
change of RMS against the model as given; a component *transfers* when it does not make the
new recording's RMS worse (RMS with it ≤ RMS without it, to 0.1 % of the RMS). Per-site or
per-camera values of sites/cameras the fit never saw cannot transfer: those rows get the
parameter's null value (no effect; a zero point of 0) and the report says so.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["Transfer", "apply_fit", "read_fit", "write_transfer_report", "TRANSFER_TOLERANCE"]

#: relative RMS change still counted as "no worse"
TRANSFER_TOLERANCE = 1e-3


@dataclass
class Transfer:
    recording: str
    fit_file: str
    n: int
    rows: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    verdict: str = ""

    def as_dict(self) -> dict:
        return {"format": "lightcurve-transfer", "format_version": 1, "recording": self.recording,
                "fit": self.fit_file, "n": self.n, "verdict": self.verdict, "components": self.rows,
                "notes": self.notes}


def read_fit(path) -> dict:
    """The ``model`` of a diagnosis.json (InputError naming the file and field)."""
    from ..io.safe_open import read_json

    p = Path(path)

    # a regular file (no FIFO or device) of at most 64 MiB, size from the opened descriptor
    js = read_json(p, max_bytes=64 * 1024 * 1024, what="diagnosis.json")
    if not isinstance(js, dict) or js.get("format") != "lightcurve-diagnosis":
        raise InputError("not a diagnosis.json", file=p, field="format",
                         value=js.get("format") if isinstance(js, dict) else None,
                         allowed="lightcurve-diagnosis")
    if js.get("format_version") != 2 or not isinstance(js.get("model"), dict):
        raise InputError("this diagnosis.json carries no fitted model (written by an older "
                         "version); diagnose the fitting recording again", file=p,
                         field="format_version", value=js.get("format_version"), allowed="2")
    if js.get("kind") != "magnitude":
        raise InputError("only lightcurve (magnitude) fits can be applied", file=p, field="kind",
                         value=js.get("kind"), allowed="magnitude")
    m = js["model"]
    for key, typ in (("free_params", dict), ("effects", list), ("channels", list)):
        if not isinstance(m.get(key), typ):
            raise InputError("malformed fitted model", file=p, field=f"model.{key}", value=m.get(key))
    return m


def _effect_terms(model, problem, fit_file, notes):
    """[(name, Effect, params)] of the fitted effects mapped onto ``problem``."""
    from ..physics import available_effects
    from .fast import diagnosis_effect

    out = []
    for i, e in enumerate(model["effects"]):
        name = e.get("name")
        if name not in available_effects("magnitude"):
            raise InputError("unknown effect in the fitted model", file=fit_file,
                             field=f"model.effects[{i}].name", value=name,
                             allowed=", ".join(available_effects("magnitude")))
        try:
            eff = diagnosis_effect(name, **(e.get("options") or {}))
        except (TypeError, ValueError) as exc:
            raise InputError(f"bad options: {exc}", file=fit_file, field=f"model.effects[{i}].options") from None
        params = {}
        specs = {s.name: s for s in eff.params}
        for k, v in (e.get("params") or {}).items():
            if k not in specs:
                raise InputError("unknown parameter", file=fit_file,
                                 field=f"model.effects[{i}].params.{k}", value=k,
                                 allowed=", ".join(specs))
            s = specs[k]
            if s.per in ("site", "camera"):
                names = problem.site_names if s.per == "site" else problem.channel_names
                nullv = s.null if s.null is not None else s.default
                vals = np.full(len(names), float(nullv))
                src = v if isinstance(v, dict) else {}
                for j, nm in enumerate(names):
                    if nm in src and src[nm] is not None:
                        vals[j] = float(src[nm])
                    else:
                        notes.append(f"{name}.{k}: no fitted value for {s.per} {nm!r}; "
                                     f"held at {nullv:g} there (does not transfer)")
                params[k] = vals
            elif isinstance(v, list):
                params[k] = np.asarray(v, float)
            elif v is not None:
                params[k] = float(v)
        try:
            params = eff.check_params(params, problem.ctx)
        except ValueError as exc:
            raise InputError(str(exc), file=fit_file, field=f"model.effects[{i}].params") from None
        out.append((name, eff, params))
    return out


def _free_theta(model, problem, fit_file, notes):
    """(problem with the fitted free parameters, theta) or (None, None) when none."""
    from .problem import _free_params

    fp = model["free_params"]
    if not fp:
        return None, None
    shape = problem.ctx.shape
    cand = {p.name: p for p in _free_params(["reflection", "zero_point"], shape, problem.channel_names)}
    free, theta = [], []
    for k, v in fp.items():
        if k not in cand:
            if k.startswith("zero_point["):
                notes.append(f"{k}: no such channel in the new recording (does not transfer)")
                continue
            raise InputError("the fitted model's surface parameter does not exist in this "
                             "recording's shape", file=fit_file, field=f"model.free_params.{k}",
                             value=k, allowed=", ".join(n for n in cand if not n.startswith("zero_point")))
        free.append(cand[k])
        theta.append(float(v))
    if not free:
        return None, None
    return problem.with_free(free), np.asarray(theta, float)


def _stats(problem, pred):
    from .selection import _pearson

    z = problem.standardized(pred)
    d = problem.y - pred
    ok = np.isfinite(d)
    return {"chi2_dof": float(z @ z) / max(problem.n, 1),
            "rms": float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else float("nan"),
            "r": _pearson(problem.y, pred), "n_unpredicted": int(np.sum(~ok))}


def apply_fit(fit_file, recording, scenario=None, *, shape=None, library_dirs=None,
              site_dirs=None) -> Transfer:
    """Predict ``recording`` with the model of ``fit_file`` (module docstring); the model of
    the recording is loaded as :func:`~.diagnose.load_problem` does (``scenario``, ``shape``,
    ``library_dirs``, ``site_dirs`` as there)."""
    from .diagnose import load_problem

    model = read_fit(fit_file)
    prob, _skip, _opts, notes = load_problem(recording, scenario, free="none", shape=shape,
                                             library_dirs=library_dirs, site_dirs=site_dirs)
    recs = [recording] if isinstance(recording, (str, Path)) else list(recording)
    tr = Transfer(recording=", ".join(Path(r).name for r in recs), fit_file=str(fit_file), n=prob.n)
    tnotes = []
    terms = _effect_terms(model, prob, fit_file, tnotes)
    fprob, theta = _free_theta(model, prob, fit_file, tnotes)
    ref = _stats(prob, prob.predict(None))
    tr.rows.append({"component": "model as given", **ref, "delta_rms": 0.0, "transfers": None})

    def row(label, pb, th, tt):
        st = _stats(pb, pb.predict(th, [(e, p) for _, e, p in tt]))
        drms = st["rms"] - ref["rms"]
        ok = bool(math.isfinite(st["rms"]) and drms <= TRANSFER_TOLERANCE * ref["rms"])
        tr.rows.append({"component": label, **st, "delta_rms": drms, "transfers": ok})

    if fprob is not None:
        row("surface refit", fprob, theta, [])
    for t in terms:
        row(t[0], prob, None, [t])
    if len(terms) + (fprob is not None) > 1:
        row("all fitted components", fprob if fprob is not None else prob, theta, terms)
    comps = [r for r in tr.rows[1:]]
    if not comps:
        tr.verdict = "the fit has nothing to apply (no effect named, nothing refitted)"
    else:
        full = comps[-1]
        bad = [r["component"] for r in comps if r["transfers"] is False]
        tr.verdict = (f"the fit {'transfers' if full['transfers'] else 'does NOT transfer'}: RMS "
                      f"{ref['rms']:.3f} as given → {full['rms']:.3f} with "
                      f"{full['component']}" + (f"; worse with: {', '.join(bad)}" if bad else ""))
    tr.notes = notes + sorted(set(tnotes))
    return tr


def write_transfer_report(tr: Transfer, out_dir) -> tuple[Path, Path]:
    """Write ``transfer.json`` and ``transfer.html`` into ``out_dir`` (atomic writes)."""
    import html

    from ..io.atomic import atomic_write_text
    from .report import _jsonable

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    js = _jsonable(tr.as_dict())
    jp = out / "transfer.json"
    atomic_write_text(jp, json.dumps(js, indent=1, allow_nan=False) + "\n")
    rows = "".join(
        f"<tr><td>{html.escape(r['component'])}</td><td>{(r['chi2_dof'] or float('nan')):.3g}</td>"
        f"<td>{(r['rms'] or float('nan')):.4f}</td><td>{(r['r'] or float('nan')):.3f}</td>"
        f"<td>{(r['delta_rms'] or 0):+.4f}</td><td>{'' if r['transfers'] is None else ('yes' if r['transfers'] else 'NO')}</td></tr>"
        for r in js["components"])
    from ..report.style import page_html

    full = [r for r in js["components"] if r["transfers"] is not None]
    level = "ok" if full and full[-1]["transfers"] and all(r["transfers"] for r in full) else (
        "warn" if full and full[-1]["transfers"] else "fail")
    body = f"""<p>Recording {html.escape(tr.recording)} ({tr.n} measurements); fit
{html.escape(Path(tr.fit_file).name)}. Nothing was refitted. A component transfers when it does
not make the RMS worse than the model as given.</p>
<table><tr><th>component</th><th>χ²/dof</th><th>RMS</th><th>Pearson R</th><th>ΔRMS vs as given</th><th>transfers</th></tr>
{rows}</table><h2>Notes</h2><ul>{''.join(f'<li>{html.escape(n)}</li>' for n in tr.notes)}</ul>"""
    page = page_html(f"Fitted model applied to {tr.recording}", (level, tr.verdict[0].upper() + tr.verdict[1:] + "."),
                     body)
    hp = out / "transfer.html"
    atomic_write_text(hp, page)
    return jp, hp
