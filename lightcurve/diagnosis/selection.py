"""Choosing effects by held-out gain: cross-validated predictions and the greedy search.

**Held-out predictions** (:func:`cv_predict`): for every fold of :mod:`.folds`, the model
(the free baseline parameters and the continuous parameters of its effect terms) is refitted
on the other folds and predicts the held-out one; every measurement is predicted once by a
model that did not see it. Fold fits start from the all-data fit (integer and grid
parameters — a CSS sensor index, a fault time — stay at their all-data values, and so does
the basin of a multimodal parameter such as a glint's orientation; the continuous values are
refitted without the held-out fold). A parameter the training folds do not constrain at all
(zero Jacobian column) is reset to its null value (no effect) or, for a baseline parameter,
to the model's value — it cannot carry information from the held-out fold.

**Held-out gain** of a model B over a model A (:func:`held_out_gain`):

    G = n ln(χ²_held(A) / χ²_held(B))

over the n held-out standardised residuals — twice the held-out Gaussian log-likelihood
ratio with the noise scale profiled out (the same form as ΔBIC's first term, but on data
the fits did not see, so no parameter-count penalty is needed: an effect that only fits noise
loses held-out likelihood). G is in units of χ² when the residuals are near their stated σ.
The held-out RMS (magnitudes or output units) and Pearson R are reported beside it.

**Greedy search** (:func:`select_effects`): starting from the baseline, every candidate (each
registry effect, and the surface refit of :mod:`.surface`) is fitted jointly with the model
so far, on all the data (in-sample χ²/dof, ΔBIC) and fold by fold (held-out χ²/dof, RMS, G);
the candidate with the largest G is added when G > ``min_gain`` (10: a held-out likelihood
ratio of e⁵ ≈ 150) *and* its parameters are identified (:mod:`.identify`); when the
candidate with the largest G is not identified it is reported as "fits, but unidentifiable
with these data" and nothing further is named. The search stops when the model is
consistent with the noise, when no candidate qualifies, or after ``max_effects`` additions.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from .baseline import fit_terms, held_names

__all__ = ["Model", "cv_predict", "held_out_gain", "held_out_summary", "MIN_GAIN"]

#: held-out gain G needed to add a candidate (module docstring)
MIN_GAIN = 10.0


@dataclass
class Model:
    """A model: the problem (with its free baseline parameters), effects with their held
    values (integer/grid/held parameters), and the all-data fit."""

    problem: object
    effects: list = field(default_factory=list)
    fixed: list = field(default_factory=list)
    fit: object = None
    names: list = field(default_factory=list)   # candidate names in order of addition

    def starts(self):
        """Start values (one combination) for refitting: the fit's effect parameters."""
        return [[dict(p) for _, p in self.fit.terms]] if self.fit is not None and self.fit.terms else None


def _null_params(effect, params):
    out = dict(params)
    for s in effect.params:
        if s.null is not None and s.name in out and s.name not in held_names(effect):
            v = out[s.name]
            out[s.name] = (np.full(np.shape(v), s.null) if np.ndim(v) else float(s.null))
    return out


def _reset_dead(fit, problem, theta0):
    """(theta, terms) of ``fit`` with unconstrained parameters reset (module docstring)."""
    theta = np.array(fit.theta, float, copy=True)
    terms = [(e, {k: (np.array(v, float, copy=True) if np.ndim(v) else v) for k, v in p.items()})
             for e, p in fit.terms]
    if fit.dead is None or not np.any(fit.dead):
        return theta, terms
    for i, (owner, spec, comp) in enumerate(fit.owners):
        if not fit.dead[i]:
            continue
        if owner == -1:
            j = [p.name for p in problem.free].index(spec.name)
            theta[j] = spec.x0
        else:
            e, p = terms[owner]
            nv = spec.null if spec.null is not None else spec.default
            if comp is None:
                p[spec.name] = float(nv)
            else:
                p[spec.name][comp] = float(nv)
    return theta, terms


def cv_predict(model: Model, folds, *, max_nfev: int = 30) -> dict:
    """Held-out predictions of ``model`` over ``folds`` (module docstring).

    Returns ``{"pred": (M,), "fold_params": [per fold: {name: value}], "n_failed": int}``.
    Models without anything to fit predict every fold with the all-data prediction.
    """
    prob = model.problem
    fit = model.fit
    pred = np.full(prob.n, np.nan)
    n_cont = 0 if fit.x is None else fit.x.size
    if n_cont == 0:
        return {"pred": np.array(fit.pred, float), "fold_params": [], "n_failed": 0}
    fold_params, failed = [], 0
    for m in folds.masks():
        train = prob.subset(~m)
        held = prob.subset(m)
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            try:
                f = fit_terms(train, model.effects, model.starts(),
                              theta0=fit.theta if prob.n_free else None, max_nfev=max_nfev,
                              fixed_effect_params=model.fixed or None)
                theta, terms = _reset_dead(f, train, fit.theta)
                pred[m] = held.predict(theta if prob.n_free else None, terms)
                fold_params.append({nm: float(v) for nm, v in zip(f.names, f.x)})
            except Exception:  # pragma: no cover - a failed fold counts as unpredicted
                failed += 1
                fold_params.append({})
    return {"pred": pred, "fold_params": fold_params, "n_failed": failed}


def _pearson(a, b):
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    if a.size < 2:
        return float("nan")
    da, db = a - a.mean(), b - b.mean()
    den = math.sqrt(float(np.sum(da * da) * np.sum(db * db)))
    return float(np.sum(da * db) / den) if den > 0 else float("nan")


def held_out_summary(problem, pred, folds=None) -> dict:
    """χ²/n, RMS (data units), Pearson R and per-fold χ² of held-out predictions."""
    z = problem.standardized(pred)
    d = problem.y - pred
    ok = np.isfinite(d)
    out = {"chi2": float(z @ z), "n": int(problem.n), "chi2_per_n": float(z @ z) / max(problem.n, 1),
           "rms": float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else float("nan"),
           "r": _pearson(problem.y, pred), "n_unpredicted": int(np.sum(~ok))}
    if folds is not None:
        out["fold_chi2"] = [float(z[m] @ z[m]) for m in folds.masks()]
    return out


def held_out_gain(before: dict, after: dict) -> float:
    """G = n ln(χ²_held(before)/χ²_held(after)) (module docstring)."""
    if before["chi2"] <= 0 or after["chi2"] <= 0:
        return float("nan")
    return float(before["n"] * math.log(before["chi2"] / after["chi2"]))


def folds_improved(before: dict, after: dict) -> int:
    """Number of folds whose held-out χ² the addition lowers."""
    fb, fa = before.get("fold_chi2"), after.get("fold_chi2")
    if not fb or not fa:
        return 0
    return int(sum(a < b for a, b in zip(fa, fb)))
