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

Coarse-sun-sensor outputs jump from cos ψ to 0 where the Sun leaves a sensor's field of view
(O'Keefe 2015 eq. 2.21): a held-out sample near an edge is predicted by a step whose position
the fold's parameters fix only to their uncertainty, and a plug-in prediction would put it a
full step off. For CSS problems the held-out prediction is therefore the posterior predictive
under the fold fit's Laplace posterior N(x̂, Σ): mean and variance over ``PREDICTIVE_DRAWS``
parameter draws (fixed seed per fold), the variance added to the noise variance of the
held-out standardised residual (Gelman et al., *Bayesian Data Analysis*, 3rd ed., §14.5, the
predictive variance σ² + Var_θ). Away from edges the added variance is O(k/n) of σ².

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
with these data" and nothing further is named. Among candidates whose gain is within one
standard error of the largest (:func:`gain_standard_error`), the one with the fewest
parameters is preferred — the one-standard-error rule of cross-validated model choice
(Hastie, Tibshirani & Friedman, *The Elements of Statistical Learning*, 2nd ed., §7.10: the
standard error of the best candidate's held-out statistic): at GEO the light time is a
near-constant delay that a clock offset of −τ reproduces to within the noise, and the
parameter-free explanation is the one to name. The search stops when the model is
consistent with the noise, when no candidate qualifies, or after ``max_effects`` additions.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from .baseline import fit_terms, held_names

__all__ = ["Model", "cv_predict", "held_out_gain", "held_out_summary", "gain_standard_error",
           "MIN_GAIN", "PREDICTIVE_DRAWS"]

#: held-out gain G needed to add a candidate (module docstring)
MIN_GAIN = 10.0
#: parameter draws of the posterior predictive of CSS held-out samples (module docstring)
PREDICTIVE_DRAWS = 16


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

    Returns ``{"pred": (M,), "pred_var": (M,) or None, "fold_params": [per fold: {name:
    value}], "n_failed": int}``. Models without anything to fit predict every fold with the
    all-data prediction. ``pred_var``: the parameter part of the predictive variance (CSS).
    """
    prob = model.problem
    fit = model.fit
    pred = np.full(prob.n, np.nan)
    n_cont = 0 if fit.x is None else fit.x.size
    if n_cont == 0:
        return {"pred": np.array(fit.pred, float), "pred_var": None, "fold_params": [],
                "n_failed": 0}
    var = np.zeros(prob.n) if prob.kind == "css" else None
    fold_params, failed = [], 0
    for j, m in enumerate(folds.masks()):
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
                if var is not None:
                    pred[m], var[m] = _predictive(held, f, theta, terms, pred[m], seed=j)
                fold_params.append({nm: float(v) for nm, v in zip(f.names, f.x)})
            except Exception:  # pragma: no cover - a failed fold counts as unpredicted
                failed += 1
                fold_params.append({})
    return {"pred": pred, "pred_var": var, "fold_params": fold_params, "n_failed": failed}


def _predictive(held, f, theta, terms, plug_in, seed):
    """Posterior-predictive mean and parameter variance of held-out measurements (module
    docstring): ``PREDICTIVE_DRAWS`` draws from N(x̂, Σ) of the fold fit ``f``, clipped to
    its bounds; dead parameters stay at their reset values."""
    if f.cov is None or f.x is None or f.x.size == 0:
        return plug_in, np.zeros_like(plug_in)
    rng = np.random.default_rng(0x5EED + seed)
    live = ~f.dead if f.dead is not None else np.ones(f.x.size, bool)
    cov = f.cov[np.ix_(live, live)]
    try:
        L = np.linalg.cholesky(0.5 * (cov + cov.T) + 1e-12 * np.eye(cov.shape[0]))
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(0.5 * (cov + cov.T))
        L = V * np.sqrt(np.clip(w, 0.0, None))
    preds = []
    for _ in range(PREDICTIVE_DRAWS):
        x = f.x.copy()
        x[live] = np.clip(f.x[live] + L @ rng.standard_normal(L.shape[1]), f.lo[live], f.hi[live])
        th, tm = _from_vector(f, x, theta, terms)
        try:
            preds.append(held.predict(th if held.n_free else None, tm))
        except (ValueError, FloatingPointError):  # pragma: no cover - a failed draw is skipped
            continue
    if len(preds) < 2:
        return plug_in, np.zeros_like(plug_in)
    P = np.array(preds)
    return P.mean(axis=0), P.var(axis=0, ddof=1)


def _from_vector(f, x, theta, terms):
    """(theta, terms) with the fitted entries of ``f`` replaced by ``x``."""
    theta = np.array(theta, float, copy=True)
    terms = [(e, {k: (np.array(v, float, copy=True) if np.ndim(v) else v) for k, v in p.items()})
             for e, p in terms]
    nb = 0
    for i, (owner, spec, comp) in enumerate(f.owners):
        if owner == -1:
            theta[nb] = x[i]
            nb += 1
        else:
            p = terms[owner][1]
            if comp is None:
                p[spec.name] = float(x[i])
            else:
                p[spec.name][comp] = float(x[i])
    return theta, terms


def _pearson(a, b):
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    if a.size < 2:
        return float("nan")
    da, db = a - a.mean(), b - b.mean()
    den = math.sqrt(float(np.sum(da * da) * np.sum(db * db)))
    return float(np.sum(da * db) / den) if den > 0 else float("nan")


def held_out_summary(problem, pred, folds=None, pred_var=None) -> dict:
    """χ²/n, RMS (data units), Pearson R and per-fold χ² of held-out predictions; with
    ``pred_var`` (the parameter part of the predictive variance) the standardised residuals
    use σ² + pred_var. ``_z2`` (per-measurement z², for :func:`gain_standard_error`) is
    internal."""
    z = problem.standardized(pred)
    if pred_var is not None:
        z = z / np.sqrt(1.0 + np.asarray(pred_var, float) / problem.sigma ** 2)
    d = problem.y - pred
    ok = np.isfinite(d)
    out = {"chi2": float(z @ z), "n": int(problem.n), "chi2_per_n": float(z @ z) / max(problem.n, 1),
           "rms": float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else float("nan"),
           "r": _pearson(problem.y, pred), "n_unpredicted": int(np.sum(~ok)), "_z2": z * z}
    if folds is not None:
        out["fold_chi2"] = [float(z[m] @ z[m]) for m in folds.masks()]
    return out


def gain_standard_error(best: dict) -> float:
    """Standard error of the held-out statistic of the best candidate, in units of G:
    G = n ln(χ²_A/χ²_held) moves with ln χ²_held, whose standard error over n independent
    held-out measurements is √(n var(z²_i))/χ²_held (delta method), so se = n √(n var(z²))/χ²
    (≈ √(2n) for Gaussian residuals). The one-standard-error rule compares the other
    candidates' gains with this (Hastie, Tibshirani & Friedman 2009, §7.10)."""
    z2 = np.asarray(best["_z2"], float)
    n = z2.size
    if n < 2 or best["chi2"] <= 0:
        return float("nan")
    return float(n * np.sqrt(n * np.var(z2, ddof=1)) / best["chi2"])


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
