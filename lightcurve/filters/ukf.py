"""Unscented quaternion estimator (USQUE) on magnitudes with GRP error sigma points.

Bernard (2021) eq. 7.51–7.87, after Crassidis & Markley (2003). Global state ``[q̂, ω̂]``
(inertial→body quaternion scalar first; body rate rad/s), error state ``[δp, δω]`` with ``δp``
the GRP (a = 1, f = 4) of ``δq = q ⊗ q̂⁻¹``; covariance P (6×6, rad² / (rad/s)²).

Propagation (Δt ≠ 0):
  sigma points ``χ = [0, ±columns of chol((n+λ) P)]`` (scaled unscented transform of
  :mod:`lightcurve.estimation.sigma_points`, parameters α, β, κ), mapped to
  ``q_i = grp2q(δp_i) ⊗ q̂``, ``ω_i = ω̂ + δω_i`` (eq. 7.60–7.66); every point propagated with the
  nonlinear dynamics; propagated errors ``δp_i = GRP(q_i⁺ ⊗ (q_0⁺)⁻¹)`` (eq. 7.67–7.70);
  mean ``x̄ = Σ Wᵐ χ⁺``, ``q̂⁻ = grp2q(δp̄) ⊗ q_0⁺``, ``ω̂⁻ = ω̄``;
  ``P⁻ = Σ Wᶜ (χ⁺ − x̄)(χ⁺ − x̄)ᵀ + Q_d`` (eq. 7.71–7.74) with ``Q_d`` the discrete process noise
  (uncontrolled η, pseudo-noise) added to the sum, and for the controlled random-walk ACS
  model ``σ_ζ² I`` on the attitude block.

Update (finite magnitude): fresh sigma points about ``q̂⁻`` from P⁻ — augmented with the ACS
jitter ζ (3 states, covariance σ_ζ² I) for the controlled "jitter" model, so the points are
``exp(ζ_i) ⊗ grp2q(δp_i) ⊗ q̂⁻`` (the controlled variant's augmented covariance,
eq. 7.83–7.87) — predicted magnitudes ``Y_i``, ``ŷ = Σ Wᵐ Y``, ``P_yy = Σ Wᶜ (Y−ŷ)² + R``,
``P_xy``, gain ``K = P_xy / P_yy``, ``δx⁺ = K ν``, ``P⁺ = P⁻ − K P_yy Kᵀ`` (eq. 7.75–7.82);
reset ``q̂ ← grp2q(δp⁺) ⊗ q̂⁻``, ``ω̂ ← ω̂⁻ + δω⁺``.

Reflection biases (``bias``, :mod:`lightcurve.filters.reflection`): the error state becomes
``[δp, δω, b_1 … b_S]`` (n = 6 + S); the bias columns of the sigma points propagate with the
diagonal linear ``Φ_b`` (plus ``Q_b``) and add to the predicted magnitude of their site,
``Y_i = m(q_i) + b̂_site + δb_i,site``; ``est.bias`` / ``est.bias_sigma`` (N,S) hold them.

Model 3 (``facets``, :mod:`lightcurve.filters.facet_states`): the unconstrained facet
parameters z are appended, ``[δp, δω, b…, z]``; each sigma point carries its own facet arrays
``p(ẑ + δz_i)`` (so the points never leave the parameter ranges), constant dynamics
(eq. 8.39, ``+ Q_z``); ``est.refl_z``/``refl_p`` (N,D) with 1σ (physical 1σ by the first-order
map ``|dp/dz| σ_z``). With ``problem.attitude_known`` (§10.7) the points share the true q, ω
of the epoch and only b, z are estimated (their propagation is then linear, ``Φ P Φᵀ + Q_d``).

Failures: a covariance whose Cholesky factor does not exist (at propagation or update)
restores the prior for that step and sets :data:`~lightcurve.filters.result.FLAG_REFUSED` (at
propagation the covariance is then propagated linearly, ``Φ P Φᵀ + Q_d``, so the filter goes
on); a sigma point predicting no reflected light skips the update
(:mod:`lightcurve.filters.gating` first skips unlit / below-horizon epochs and gates the
innovation with ``S = P_yy``, including R, over the sigma points)
(:data:`~lightcurve.filters.result.FLAG_INVISIBLE`). Never a silent NaN.

Deviation from a fully augmented USQUE: the process noise enters additively (``+ Q_d``) rather
than as augmented sigma-point columns, and the measurement noise is additive (``+ R``); for the
additive Gaussian noises of these models the two are equivalent to second order.
"""

from __future__ import annotations

import numpy as np

from ..core.rotations import perturb_rotvec_nb
from ..estimation.sigma_points import sigma_offsets, unscented_update, unscented_weights
from .config import UKFConfig
from ._common import FilterProblem, StateLayout, apply_grp, grp_rel, single_thread
from .driver import StepBase, run_kalman
from .result import FLAG_INVISIBLE, FLAG_REFUSED, Estimate

__all__ = ["run_ukf"]


def run_ukf(problem: FilterProblem, config: UKFConfig | None = None, *, alpha=None, beta=None,
            kappa=None, bias=None, facets=None) -> Estimate:
    """Run the USQUE/GRP UKF over every epoch (module docstring) → :class:`Estimate`.

    ``config``: :class:`~lightcurve.filters.config.UKFConfig` (default settings); ``alpha``,
    ``beta``, ``kappa`` override its scaled-unscented parameters (λ = α²(n+κ) − n, with n = 6,
    or 9 when the ACS jitter is augmented at the update; + S with ``bias``, + D with
    ``facets``; − 6 when ``problem.attitude_known``).
    ``bias``: :class:`lightcurve.filters.reflection.SiteBias` or None.
    ``facets``: :class:`lightcurve.filters.facet_states.FacetParameterStates` or None (Model 3).
    """
    config = UKFConfig.resolve(config, alpha=alpha, beta=beta, kappa=kappa)
    problem.meta.setdefault("variant", config.variant)
    alpha, beta, kappa = config.alpha, config.beta, config.kappa
    L = StateLayout(not problem.attitude_known, bias, facets)
    if L.nx == 0:
        raise ValueError("attitude known and no extra state: nothing to estimate")
    w6 = unscented_weights(L.nx, alpha, beta, kappa)
    w9 = (unscented_weights(L.nx + 3, alpha, beta, kappa)
          if problem.jitter_zeta() and L.na else None)
    with single_thread():
        return run_kalman(problem, _UKFStep(problem, w6, w9, bias, facets), bias, facets)


def _sigma_states(q, w, off6, na):
    """Quaternions and rates of the sigma points: centre + offsets (2n, nx) (the attitude
    columns when ``na`` = 6; all points share q, ω when the attitude is known)."""
    chi = np.vstack([np.zeros((1, off6.shape[1])), off6])
    if na:
        Q = apply_grp(chi[:, :3], q)
        W = w[None, :] + chi[:, 3:6]
    else:
        Q = np.repeat(q[None, :], chi.shape[0], axis=0)
        W = np.repeat(w[None, :], chi.shape[0], axis=0)
    return chi, Q, np.ascontiguousarray(W)


class _UKFStep(StepBase):
    """The USQUE time and measurement updates (module docstring) for
    :func:`lightcurve.filters.driver.run_kalman`."""

    method = "ukf"
    gate_auto = "reject"

    def __init__(self, problem, w6, w9, bias, facets):
        super().__init__(problem, bias, facets)
        self.w6 = w6
        self.w9 = w9

    def predict(self, x, k, dt, Phi, Qd, phib, rec):
        L = x.layout
        na, nb, nz = L.na, L.nb, L.nz
        off, ok = sigma_offsets(x.P, self.w6) if na else (None, False)
        if ok:
            chi, Qs, Ws = _sigma_states(x.q, x.w, off, na)
            Qp, Wp = self.p.dynamics.propagate(Qs, Ws, dt)
            dp = grp_rel(Qp, Qp[0])
            cols = [dp, Wp]
            if nb:
                cols.append((x.b + chi[:, L.ib]) * phib)
            if nz:
                cols.append(x.z + chi[:, L.iz])
            X = np.hstack(cols)
            xm = self.w6.wm @ X
            D = X - xm
            x.P = (D * self.w6.wc[:, None]).T @ D + Qd
            x.q = apply_grp(xm[None, :3], Qp[0])[0]
            x.w = xm[3:6].copy()
            x.b = xm[L.ib].copy()
            x.z = xm[L.iz].copy()
            return
        # attitude known (the extra states are linear: exact Φ P Φᵀ + Q_d), or a refused
        # factorisation (flagged; linear propagation so the filter goes on)
        if na:
            rec.flags[k] |= FLAG_REFUSED
            Qn, Wn = self.p.dynamics.propagate(x.q[None, :], x.w[None, :], dt)
            x.q, x.w = Qn[0], Wn[0]
        if nb:
            x.b = phib * x.b
        x.P = Phi @ x.P @ Phi.T + Qd

    def update(self, x, k, y, rec):
        x.q, x.w, x.b, x.z, x.P = _epoch(self.p, k, y, x.q, x.w, x.b, x.z, x.P, x.layout,
                                         self.w6, self.w9, self.zc, rec, self.bias,
                                         self.facets)


def _epoch(p, k, y, q, w, b, z, P, L, w6, w9, zc, rec, bias, facets):
    """Measurement update of epoch k with the magnitude y → the new (q, w, b, z, P) (the prior
    when refused or gated out)."""
    m = p.model
    nx, na, nb, nz = L.nx, L.na, L.nb, L.nz
    prior = (q, w, b, z, P)
    wts = w9 if w9 is not None else w6
    Pa = P
    if w9 is not None:
        Pa = np.zeros((nx + 3, nx + 3))
        Pa[:nx, :nx] = P
        Pa[nx:, nx:] = zc
    off, ok = sigma_offsets(Pa, wts)
    if not ok:
        rec.flags[k] |= FLAG_REFUSED
        return prior
    chi, Qs, Ws = _sigma_states(q, w, off, na)
    if w9 is not None:
        Qs = perturb_rotvec_nb(np.ascontiguousarray(Qs), np.ascontiguousarray(chi[:, nx:nx + 3]))
    if nz:
        Y = facets.magnitudes(m, Qs, z + chi[:, L.iz], k)
    else:
        Y = m.predict_q(Qs, k)
    if not np.all(np.isfinite(Y)):
        rec.flags[k] |= FLAG_INVISIBLE
        return prior
    if nb:
        s = int(bias.site[k])
        Y = Y + b[s] + chi[:, na + s]
    # innovation gate on ν = y − Σ Wᵐ Y with S = Σ Wᶜ (Y − ŷ)² + R; None = outlier rejected
    ym = float(wts.wm @ Y)
    R = rec.gate.check(k, y - ym, float(wts.wc @ (Y - ym) ** 2) + m.sigma[k] ** 2,
                       m.sigma[k] ** 2, rec)
    if R is None:
        return prior
    dx, Pn, info = unscented_update(np.zeros(nx), P, chi[:, :nx], Y[:, None], np.array([y]),
                                    wts, R=R)
    rec.innovation(k, float(info.innovation[0]), float(info.S[0, 0]))
    if info.ok:
        if na:
            q, w = apply_grp(dx[None, :3], q)[0], w + dx[3:6]
        return q, w, b + dx[L.ib], z + dx[L.iz], Pn
    rec.flags[k] |= FLAG_REFUSED
    return prior
