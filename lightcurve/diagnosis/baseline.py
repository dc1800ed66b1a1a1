"""Least-squares fits of the baseline model and of effect terms (scipy ``least_squares``).

The objective is Σ z², z = (y − ŷ(θ, φ))/σ (:meth:`Problem.standardized`), over the free
baseline parameters θ (:class:`~.problem.FreeParam`, bounded) and the continuous parameters
φ of the effect terms. Effect-parameter bounds are the *prior's* support (uniform and
log-uniform: [a, b]; signed uniform: [−b, b]; normal: mean ± 4 sd) widened by a quarter of
its span on each side (in log space for log-uniform priors; angles by 90°) and intersected
with the parameter's allowed range: the fit looks for realistic values, and a true value
anywhere inside the prior's support is never pinned at a fit bound (a fitted value at a
bound therefore means "not identified", :mod:`.identify`). Integer parameters (a CSS sensor
index) and step times (``t_start_s``) are not differentiable: they are held at the values of
each start and enumerated by the caller (:mod:`.candidates`); so are the parameters an
effect lists in ``hold`` (held at a reference value when the data do not identify them) and
in its class attribute ``diagnosis_hold`` (parameters only identifiable in combination with
others, e.g. a common CSS scale factor with the individual ones); single components of a
per-site/camera/sensor parameter listed in ``hold_components`` are held likewise.

Uncertainties: the covariance of the fitted vector is (JᵀJ)⁺ (J the Jacobian of z at the
solution), scaled by max(1, χ²/dof) — the usual inflation when the residuals are wider
than their stated σ. Reported 1σ values are its diagonal's square roots; parameters the data
do not constrain at all (a zero Jacobian column) have no uncertainty (``dead``).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

__all__ = ["Fit", "typical_params", "fit_terms", "fit_baseline", "param_layout", "GRID_PARAMS",
           "prior_bounds", "prior_support", "held_names", "BOUND_MARGIN"]

#: effect parameters that are stepped by the caller rather than optimised
GRID_PARAMS = ("t_start_s",)


def typical_params(effect, ctx=None) -> dict:
    """Parameters of typical size of an effect (:meth:`Effect.typical_params`)."""
    return effect.typical_params(ctx)


#: fraction of the prior's span added on each side for the fit bounds
BOUND_MARGIN = 0.25


def prior_support(spec) -> tuple[float, float]:
    """The support of a parameter's prior (normal: mean ± 4 sd), within its allowed range."""
    pr = spec.prior
    if pr.kind in ("uniform", "log_uniform"):
        lo, hi = pr.a, pr.b
    elif pr.kind == "signed_uniform":
        lo, hi = -pr.b, pr.b
    elif pr.kind == "normal":
        lo, hi = pr.a - 4 * pr.b, pr.a + 4 * pr.b
    else:
        lo, hi = spec.min, spec.max
    return float(max(lo, spec.min)), float(min(hi, spec.max))


def prior_bounds(spec) -> tuple[float, float]:
    """Fit bounds of one :class:`~lightcurve.physics.ParamSpec` (module docstring)."""
    lo, hi = prior_support(spec)
    pr = spec.prior
    if spec.name.endswith("_deg") and pr.kind == "uniform" and pr.b - pr.a >= 180:
        # angles: allow wrapping past the prior's edges (the optimiser should not get stuck there)
        lo, hi = lo - 90.0, hi + 90.0
    elif pr.kind == "log_uniform":
        f = (hi / lo) ** BOUND_MARGIN
        lo, hi = lo / f, hi * f
    elif np.isfinite(hi - lo):
        d = BOUND_MARGIN * (hi - lo)
        lo, hi = lo - d, hi + d
    return float(max(lo, spec.min)), float(min(hi, spec.max))


def held_names(effect) -> set:
    """Names of the effect's parameters that fits hold fixed (integer, grid, held)."""
    return ({s.name for s in effect.params if s.integer or s.name in GRID_PARAMS}
            | set(getattr(effect, "hold", ()) or ()) | set(getattr(effect, "diagnosis_hold", {}) or {}))


@dataclass
class _Layout:
    effect: object
    entries: list          # (spec, component index or None)
    fixed: tuple           # names of parameters held fixed (integer / grid)
    sizes: dict

    @property
    def n(self) -> int:
        return len(self.entries)

    def bounds(self):
        b = [prior_bounds(s) for s, _ in self.entries]
        return np.array([x[0] for x in b]), np.array([x[1] for x in b])

    def pack(self, params) -> np.ndarray:
        out = []
        for s, c in self.entries:
            v = params[s.name]
            out.append(float(v) if c is None else float(np.asarray(v)[c]))
        return np.array(out, float)

    def unpack(self, x, base) -> dict:
        p = {k: (np.array(v, float, copy=True) if np.ndim(v) else float(v)) for k, v in base.items()}
        for (s, c), v in zip(self.entries, x):
            if c is None:
                p[s.name] = float(v)
            else:
                p[s.name][c] = float(v)
        return p


def param_layout(effect, ctx) -> _Layout:
    """The continuous-parameter layout of ``effect`` for context ``ctx``."""
    entries, fixed, sizes = [], [], {}
    hold = held_names(effect)
    for s in effect.params:
        if s.name in hold:
            fixed.append(s.name)
            continue
        n = effect._size(s, ctx)
        sizes[s.name] = n
        if n is None:
            entries.append((s, None))
        else:
            off = (getattr(effect, "hold_components", None) or {}).get(s.name, ())
            entries.extend((s, k) for k in range(n) if k not in off)
    return _Layout(effect, entries, tuple(fixed), sizes)


@dataclass
class Fit:
    """Result of a fit: baseline vector ``theta``, effect ``terms`` [(Effect, params)], the
    prediction, standardised residuals, χ², covariance of the fitted vector, names."""

    theta: np.ndarray
    terms: list
    pred: np.ndarray
    z: np.ndarray
    chi2: float
    names: list = field(default_factory=list)
    x: np.ndarray | None = None
    sd: np.ndarray | None = None
    n_effect_params: int = 0
    success: bool = True
    message: str = ""
    #: covariance of ``x`` (scaled as the module docstring says), fit bounds of ``x``
    cov: np.ndarray | None = None
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    #: (len(x),) True where the Jacobian column is zero (the data do not constrain it)
    dead: np.ndarray | None = None
    #: owner of each entry of ``x``: (-1, FreeParam, None) for baseline parameters,
    #: (effect index, ParamSpec, component or None) for effect parameters
    owners: list = field(default_factory=list)

    @property
    def n_params(self) -> int:
        return int(self.theta.size + self.n_effect_params)

    def rms(self, y) -> float:
        d = np.asarray(y) - self.pred
        d = d[np.isfinite(d)]
        return float(np.sqrt(np.mean(d * d))) if d.size else float("nan")


def _clip_into(x, lo, hi):
    span = hi - lo
    eps = np.where(np.isfinite(span), 1e-9 * np.maximum(span, 1e-12), 1e-9)
    return np.minimum(np.maximum(x, lo + eps), hi - eps)


def fit_terms(problem, effects=(), starts=None, *, theta0=None, fit_theta: bool = True,
              max_nfev: int = 60, fixed_effect_params=None) -> Fit:
    """Fit the baseline θ and the continuous parameters of ``effects`` jointly.

    ``starts``: list of start combinations; each a list (one dict per effect) of parameter
    values (missing names → the effect's typical values). The best (lowest χ²) result is
    returned. ``fixed_effect_params``: per effect, dict of integer/grid values to hold.
    """
    effects = list(effects)
    ctx = problem.ctx
    layouts = [param_layout(e, ctx) for e in effects]
    th0 = problem.x0() if theta0 is None else np.asarray(theta0, float)
    lo_b, hi_b = problem.bounds()
    nth = th0.size if fit_theta else 0
    if starts is None or not starts:
        starts = [[{} for _ in effects]]
    fixed_effect_params = fixed_effect_params or [{} for _ in effects]
    base_params = []
    for e, fx in zip(effects, fixed_effect_params):
        bp = typical_params(e, ctx)
        bp.update(fx)
        base_params.append(e.check_params(bp, ctx) if not any(
            s.integer for s in e.params) else bp)
    los = [lo_b[:nth]] + [L.bounds()[0] for L in layouts]
    his = [hi_b[:nth]] + [L.bounds()[1] for L in layouts]
    lo = np.concatenate(los) if los else np.zeros(0)
    hi = np.concatenate(his) if his else np.zeros(0)

    def split(x):
        theta = x[:nth] if fit_theta else th0
        terms, k = [], nth
        for e, L, bp in zip(effects, layouts, base_params):
            terms.append((e, L.unpack(x[k:k + L.n], bp)))
            k += L.n
        return theta, terms

    def resid(x):
        theta, terms = split(x)
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                pred = problem.predict(theta, terms)
            except (ValueError, FloatingPointError):
                return np.full(problem.n, 1e3)
        return problem.standardized(pred)

    best = None
    for st in starts:
        parts = [th0[:nth]]
        for e, L, bp, sp in zip(effects, layouts, base_params, st):
            p = dict(bp)
            p.update({k: v for k, v in sp.items() if k not in L.fixed})
            parts.append(L.pack(p))
        x0 = np.concatenate(parts) if parts else np.zeros(0)
        if x0.size == 0:
            r = resid(x0)
            res = _Res(x0, r, np.zeros((r.size, 0)))
        else:
            x0 = _clip_into(x0, lo, hi)
            try:
                res = least_squares(resid, x0, bounds=(lo, hi), x_scale="jac", max_nfev=max_nfev,
                                    method="trf", diff_step=1e-4)
            except (ValueError, np.linalg.LinAlgError) as exc:  # pragma: no cover - defensive
                res = _Res(x0, resid(x0), np.zeros((problem.n, x0.size)), str(exc))
        c2 = float(res.fun @ res.fun)
        if best is None or c2 < best[0]:
            best = (c2, res)
    c2, res = best
    theta, terms = split(res.x)
    pred = problem.predict(theta, terms) if res.x.size or not effects else problem.predict(theta, terms)
    z = problem.standardized(pred)
    names = [p.name for p in problem.free][:nth]
    for e, L in zip(effects, layouts):
        for s, c in L.entries:
            sname = s.name if c is None else f"{s.name}[{_comp_name(problem, s, c)}]"
            names.append(f"{e.name}.{sname}")
    owners = [(-1, p, None) for p in problem.free][:nth]
    for i, L in enumerate(layouts):
        owners.extend((i, s, c) for s, c in L.entries)
    sd = cov = dead = None
    if res.x.size:
        J = np.asarray(res.jac, float)
        dof = max(problem.n - res.x.size, 1)
        scale = max(1.0, c2 / dof)
        dead = ~np.any(J != 0, axis=0)
        try:
            cov = np.linalg.pinv(J.T @ J) * scale
            sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
            # parameters the data do not constrain (zero Jacobian column): unknown
            sd[dead] = np.nan
        except np.linalg.LinAlgError:  # pragma: no cover
            sd = np.full(res.x.size, np.nan)
    n_eff = sum(L.n + len(L.fixed) for L in layouts)
    return Fit(theta=np.asarray(theta, float), terms=terms, pred=pred, z=z, chi2=float(z @ z),
               names=names, x=np.asarray(res.x, float), sd=sd, n_effect_params=n_eff,
               success=bool(getattr(res, "success", True)), message=str(getattr(res, "message", "")),
               cov=cov, lo=lo, hi=hi, dead=dead, owners=owners)


class _Res:
    def __init__(self, x, fun, jac, message=""):
        self.x, self.fun, self.jac, self.message, self.success = x, fun, jac, message, True


def _comp_name(problem, spec, c):
    if problem.kind == "magnitude" and spec.per in ("site", "camera"):
        names = problem.site_names if spec.per == "site" else problem.channel_names
        if c < len(names):
            return names[c]
    return str(c)


def fit_baseline(problem, *, max_nfev: int = 100) -> Fit:
    """Fit the free baseline parameters (no effect). With none free: the model as given."""
    if problem.n_free == 0:
        pred = problem.predict(None)
        z = problem.standardized(pred)
        return Fit(theta=np.zeros(0), terms=[], pred=pred, z=z, chi2=float(z @ z))
    return fit_terms(problem, [], None, max_nfev=max_nfev)


def bic_gain(chi2_0: float, chi2_1: float, n: int, k_extra: int) -> float:
    """ΔBIC = BIC(baseline) − BIC(with effect) for Gaussian residuals with the noise scale
    profiled out: n ln(χ²₀/χ²₁) − k ln n (Schwarz 1978). Positive favours the effect; > 10 is
    "very strong" evidence (Kass & Raftery 1995)."""
    if chi2_1 <= 0 or chi2_0 <= 0:
        return float("nan")
    return float(n * math.log(chi2_0 / chi2_1) - k_extra * math.log(n))


__all__.append("bic_gain")
