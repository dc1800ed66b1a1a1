"""Reflection-parameter uncertainty as extra filter states: per-site magnitude biases.

Real surfaces age, so the shape file's reflection parameters p (ξ, a = F0, m per Cook–Torrance
facet, and the facet areas A) are uncertain. Bernard (2021) ch. 8 absorbs the resulting model
error into a magnitude bias ``b_s`` per observing site s, appended to the filter state
``[δθ, δω, b_1 … b_S]`` with the measurement ``y = m(q) + b_site + v``. Three bias dynamics:

* ``"random-walk"`` — Holzinger's baseline (eq. 8.3): ``ḃ = w``, white w of PSD ``q_rw``
  (mag²/s), discrete ``Φ = 1``, ``Q_d = q_rw Δt``. Documented simplification of eq. 8.4: the
  strength is chosen so that the bias variance grows by the Model 1 prior variance σ_b² over
  the lightcurve's duration T, ``q_rw = σ_b² / T``.
* ``"model1"`` — constant bias (``Φ = 1``, ``Q_d = 0``), prior variance from eq. 8.10:
  ``σ_b² = Σ_p (∂m/∂p)² σ_p²`` over every reflection parameter p of every Cook–Torrance facet
  (ξ_i, a_i, m_i, A_i), with ``σ_p = frac · p`` (10 % by default, the §10.1 truth
  perturbation) and the analytic partials of :func:`lightcurve.photometry.magnitude_partials`.
  The partials depend on the geometry, so σ_b² of a site is their epoch mean over that site's
  measurements, evaluated along the filter's *prior* attitude history (the initial estimate
  propagated with the filter's dynamics, no measurement used) — stated here, not hidden.
* ``"model2"`` — first-order Gauss–Markov bias ``ḃ = −b/τ + w`` with ``τ = 0.1 · 2π/|ω̂|``
  (eq. 8.12, one tenth of the current estimated spin period) and PSD ``Q = 2σ_b²/τ``
  (eq. 8.13), so the stationary variance is σ_b². Exact discrete transition
  ``Φ = exp(−Δt/τ)``, ``Q_d = σ_b² (1 − exp(−2Δt/τ))``. As ``|ω̂| → 0`` τ → ∞ and the model
  tends to Model 1; τ is capped at ``tau_max_s`` (default: the lightcurve's duration, at
  least 1 s), which keeps Φ and Q_d finite and well conditioned.

Model 3 (direct estimation of the facet parameters ξ, a, m, A in unconstrained coordinates,
eq. 8.39–8.44) is :class:`lightcurve.filters.facet_states.FacetParameterStates`, appended to
the same filter state after the biases; the batch posterior of the same parameters is
:mod:`lightcurve.studies.fit_reflection`.
"""

from __future__ import annotations

import numpy as np

from ..core.photometry import COOK_TORRANCE
from ..errors import InputError
from ..photometry.partials import magnitude_partials

__all__ = ["BIAS_MODELS", "REFLECTION_CHOICES", "SiteBias", "reflection_prior_variance"]

#: per-site magnitude-bias models (:class:`SiteBias`)
BIAS_MODELS = ("random-walk", "model1", "model2")
#: values of ``lightcurve invert --reflection``: no extra state, a bias model, or Model 3
#: (facet-parameter states, :mod:`lightcurve.filters.facet_states`)
REFLECTION_CHOICES = ("none",) + BIAS_MODELS + ("model3",)


def reflection_prior_variance(shape, q, model, frac=0.1, epochs=None):
    """Eq. 8.10: per-epoch magnitude variance from uncertain reflection parameters, mag².

    ``Σ_i [(∂m/∂ξ_i σ_ξ)² + (∂m/∂a_i σ_a)² + (∂m/∂m_i σ_m)² + (∂m/∂A_i σ_A)²]`` with
    ``σ_p = frac · p`` over the Cook–Torrance facets (other facets contribute their area term
    only). ``q`` (N,4) inertial→body attitudes at ``model.t[epochs]``; ``model`` a
    :class:`~lightcurve.filters.models.MagnitudeModel`. Returns (N,) (NaN where m = +inf).
    """
    idx = np.arange(len(model)) if epochs is None else np.asarray(epochs, int)
    with np.errstate(divide="ignore", invalid="ignore"):
        mp = magnitude_partials(shape, np.asarray(q, float), model.s_eci[idx], model.o_eci[idx],
                                model.range_obs[idx], model.range_sun[idx], sun_mag=model.sun_mag)
    ct = shape.model_ids == COOK_TORRANCE
    var = (mp.dm_dA * frac * shape.areas_m2[None, :]) ** 2
    for name, col in (("dm_dxi", 0), ("dm_da", 1), ("dm_dm", 2)):
        d = getattr(mp, name)[:, ct] * frac * shape.params[ct, col][None, :]
        var[:, ct] += d * d
    out = np.sum(var, axis=1)
    return np.where(np.isfinite(mp.m), out, np.nan)


class SiteBias:
    """Per-site magnitude-bias states for the MEKF and the UKF (module docstring).

    Parameters
    ----------
    kind : {"random-walk", "model1", "model2"}
    site : (N,) int site index of every epoch
    var0 : (S,) prior (Model 1) variance per site, mag² (> 0)
    duration_s : float, the lightcurve's duration T (random-walk strength, τ cap)
    tau_max_s : float or None — Model 2 τ cap (default max(T, 1 s))
    """

    def __init__(self, kind, site, var0, duration_s, tau_max_s=None):
        if kind not in BIAS_MODELS:
            raise InputError("unknown reflection bias model", field="reflection", value=kind,
                             allowed=", ".join(BIAS_MODELS))
        self.kind = kind
        self.site = np.asarray(site, np.int64)
        self.var0 = np.asarray(var0, float).reshape(-1)
        if np.any(~(self.var0 > 0)) or not np.all(np.isfinite(self.var0)):
            raise ValueError(f"prior bias variances must be finite and > 0, got {self.var0}")
        self.n_sites = self.var0.size
        if self.site.size and (self.site.min() < 0 or self.site.max() >= self.n_sites):
            raise ValueError("site index out of range of the bias variances")
        T = max(float(duration_s), 1.0)
        self.duration_s = T
        self.tau_max_s = T if tau_max_s is None else float(tau_max_s)
        if not self.tau_max_s > 0:
            raise ValueError(f"tau_max_s must be > 0, got {tau_max_s}")
        self.q_rw = self.var0 / T                       # mag²/s, random-walk strength

    @classmethod
    def from_problem(cls, kind, problem, frac=0.1, tau_max_s=None):
        """Build from a :class:`~lightcurve.filters._common.FilterProblem`: σ_b² per site from
        eq. 8.10 averaged over that site's measured epochs along the prior attitude history."""
        m = problem.model
        site = np.asarray(getattr(m, "site", np.zeros(len(m), np.int64)), np.int64)
        n_sites = int(site.max()) + 1 if site.size else 1
        dyn = problem.dynamics
        q, w = problem.q0[None, :].copy(), problem.omega0[None, :].copy()
        Q = np.empty((len(m), 4))
        for k in range(len(m)):
            if k > 0 and m.t[k] != m.t[k - 1]:
                q, w = dyn.propagate(q, w, float(m.t[k] - m.t[k - 1]))
            Q[k] = q[0]
        v = reflection_prior_variance(m.shape, Q, m, frac=frac)
        var0 = np.empty(n_sites)
        for s in range(n_sites):
            sel = (site == s) & np.isfinite(m.y) & np.isfinite(v)
            var0[s] = float(np.mean(v[sel])) if np.any(sel) else float(np.nanmean(v))
        if not np.all(np.isfinite(var0) & (var0 > 0)):
            raise InputError("eq. 8.10 prior bias variance is not positive for every site (no "
                             "reflected light along the prior attitude history?)",
                             field="reflection", value=var0.tolist())
        return cls(kind, site, var0, float(m.t[-1] - m.t[0]), tau_max_s=tau_max_s)

    def tau(self, omega):
        """Model 2 correlation time, s: 0.1·2π/|ω| (eq. 8.12), capped at ``tau_max_s``."""
        nw = float(np.linalg.norm(omega))
        if nw <= 0.0:
            return self.tau_max_s
        return min(0.1 * 2.0 * np.pi / nw, self.tau_max_s)

    def transition(self, dt, omega):
        """Diagonal ``(Φ_b (S,), Q_b (S,))`` of the bias block over dt s at the rate ω (rad/s)."""
        dt = float(dt)
        S = self.n_sites
        if self.kind == "model1":
            return np.ones(S), np.zeros(S)
        if self.kind == "random-walk":
            return np.ones(S), self.q_rw * abs(dt)
        tau = self.tau(omega)
        e = np.exp(-abs(dt) / tau)
        return np.full(S, e), self.var0 * (1.0 - e * e)

    def describe(self) -> dict:
        """JSON-ready settings."""
        return {"model": self.kind, "prior_sigma_mag": np.sqrt(self.var0).tolist(),
                "random_walk_psd_mag2_s": self.q_rw.tolist() if self.kind == "random-walk" else None,
                "tau_max_s": self.tau_max_s if self.kind == "model2" else None}
