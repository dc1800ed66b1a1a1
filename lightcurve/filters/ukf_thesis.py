"""Bernard (2021) §7.2 USQUE UKF exactly as written: the ``variant = "thesis"`` UKF.

The differences from :mod:`lightcurve.filters.ukf` (our ``"robust"`` UKF) are those of the
text (Crassidis & Markley 2003 as Bernard tabulates it, Tables 7.3–7.4, eq. 7.51–7.96):

* one fully augmented sigma-point set per step, drawn at the previous epoch from
  ``Pᵃ = blockdiag(P, Q, R)`` (eq. 7.60–7.64, 7.83–7.84, 7.95) and propagated; the same points
  give the time update (eq. 7.71–7.74) and the measurement update (eq. 7.75–7.82) — no redraw
  from P⁻;
* the noises are sigma-point columns, not additive terms: the measurement noise ν (R) is
  added to the predicted magnitudes of its columns (eq. 7.75, ``g = h + ν``); for the
  controlled model the ACS error ζ (Q_ζ) perturbs the propagated attitudes of its columns
  before the measurement, ``δq(ζ_i) ⊗ χ_i`` (eq. 7.86–7.87), and not the time update (the
  covariance does not grow, §7.2.2); for the uncontrolled model the process noise
  ``Q_η,d = Q_η Δt`` (eq. 7.95) is a rate increment of its columns at the start of the step
  (the text applies it "in the dynamics"; its covariance ``Q_η Δt`` is that of a rate change
  — the reading chosen once here);
* no innovation gate (ch. 7 has none: ``invert`` sets the gate "off" for the thesis variant);
  epochs whose object is below the horizon are still skipped (:mod:`lightcurve.filters.gating`
  screening), as in every variant. A gate given explicitly (an ablation) acts as in the robust
  UKF: a rejected magnitude leaves the time update, an inflated one adds ``R' − R`` to ``P_yy``.

Reading chosen for eq. 7.91 (the text converts the perturbed points "back into error GRPs"):
the cross-covariance uses the error GRPs of the propagated, *unperturbed* points, i.e. ζ
enters the update only through the predicted magnitudes — the same treatment as the MEKF's
eq. 7.27 (``R + H Q_ζ Hᵀ``); with the perturbed points the update would subtract from P a
variance (Q_ζ) it never contained.

α, β, κ: §7.2 defines λ = α²(L + κ) − L (eq. 7.64) but gives no values, §6.2.2 only the
ranges (0 < α ≤ 1, β = 2 for a Gaussian, κ ≥ 0); chosen once for every case: α = 0.25, β = 2,
κ = 0 (:data:`lightcurve.filters.config.UKF_DEFAULT_ALPHA` says how α was chosen).

Extra states (reflection biases, Model 3 parameters): their columns propagate with their
linear dynamics (``Φ_b``, identity) and their process noise is additive (``+ Q_b``, ``+ Q_z``):
ch. 8 does not say how the UKF carries them. With the attitude known (§10.7) only those states
are estimated.
"""

from __future__ import annotations

import time

import numpy as np

from ..core.rotations import perturb_rotvec_nb
from ..estimation.kalman import safe_cholesky
from ..estimation.sigma_points import unscented_weights
from ._common import (
    FilterProblem,
    Recorder,
    StateLayout,
    apply_grp,
    attach_histories,
    grp_rel,
    initial_state_ext,
    layout_transition,
    reflection_histories,
    single_thread,
    store_epoch,
    truth_state,
)
from .gating import InnovationGate
from .result import FLAG_INVISIBLE, FLAG_NAN, FLAG_REFUSED, Estimate

__all__ = ["run_ukf_thesis"]


def run_ukf_thesis(problem: FilterProblem, config=None, *, alpha=None, beta=None, kappa=None,
                   bias=None, facets=None) -> Estimate:
    """Run Bernard's §7.2 UKF over every epoch (module docstring) → :class:`Estimate`.

    ``config``: a :class:`~lightcurve.filters.config.UKFConfig` (its α, β, κ; default the
    thesis variant's 0.25, 2, 0); the keywords ``alpha``, ``beta``, ``kappa`` override it."""
    from .config import UKFConfig

    cfg = UKFConfig.resolve(UKFConfig(variant="thesis") if config is None else config,
                            alpha=alpha, beta=beta, kappa=kappa)
    problem.meta.setdefault("variant", "thesis")
    L = StateLayout(not problem.attitude_known, bias, facets)
    if L.nx == 0:
        raise ValueError("attitude known and no extra state: nothing to estimate")
    with single_thread():
        return _run(problem, L, cfg.alpha, cfg.beta, cfg.kappa, bias, facets)


def _noise_dims(p, L):
    """Sizes of the augmented noise blocks: (attitude noise 0 or 3, measurement 1)."""
    d = p.dynamics
    if not L.na:
        return 0
    if d.kind == "controlled":
        return 3 if d.acs_sigma > 0.0 else 0
    return 3 if d.eta_psd > 0.0 else 0


def _run(p, L, alpha, beta, kappa, bias, facets):
    t0 = time.perf_counter()
    m = p.model
    dyn = p.dynamics
    rec = Recorder(p, "ukf")
    p.meta.setdefault("gate", {"mode": "off"})
    gate = InnovationGate(p)
    _, q, w, b, z, P = initial_state_ext(p, bias, facets)
    na, nb, nz, nx = L.na, L.nb, L.nz, L.nx
    nq = _noise_dims(p, L)
    n_aug = nx + nq + 1
    wts = unscented_weights(n_aug, alpha, beta, kappa)
    hists = reflection_histories(p.n, nb, nz)
    controlled = dyn.kind == "controlled"
    for k in range(p.n):
        dt = float(m.t[k] - m.t[k - 1]) if k > 0 else 0.0
        if not na:
            q, w = truth_state(p, k)
        y = m.y[k]
        use = np.isfinite(y) and not gate.skip_epoch(k, rec)
        if not np.isfinite(y):
            rec.flags[k] |= FLAG_NAN
            rec.skipped_nan += 1
        R = float(m.sigma[k] ** 2) if use else 1.0
        # ---- augmented sigma points at the previous epoch (eq. 7.62, 7.84, 7.95) ----------
        # Pᵃ is block diagonal: its Cholesky factor is the blocks' (a zero noise block — no
        # step yet — gives columns equal to the centre)
        Lp, ok = safe_cholesky(P)
        if not ok:
            rec.flags[k] |= FLAG_REFUSED
            q, w, b, P = _linear_step(p, L, bias, facets, q, w, b, P, dt)
            store_epoch(rec, k, L, q, w, b, z, P, hists)
            continue
        La = np.zeros((n_aug, n_aug))
        La[:nx, :nx] = Lp
        if nq:
            qvar = dyn.acs_sigma ** 2 if controlled else dyn.eta_psd * max(dt, 0.0)
            La[nx:nx + 3, nx:nx + 3] = np.sqrt(qvar) * np.eye(3)
        La[-1, -1] = np.sqrt(R)
        Sg = np.sqrt(n_aug + wts.lam) * La.T
        off = np.concatenate([Sg, -Sg], axis=0)
        chi = np.vstack([np.zeros((1, n_aug)), off])
        S = chi.shape[0]
        # quaternions and rates of the points (eq. 7.65–7.68)
        if na:
            Qs = apply_grp(chi[:, :3], q)
            Ws = np.ascontiguousarray(w[None, :] + chi[:, 3:6])
            if nq and not controlled:
                Ws = np.ascontiguousarray(Ws + chi[:, nx:nx + 3])   # η as a rate increment
            if dt != 0.0:
                Qs, Ws = dyn.propagate(Qs, Ws, dt)                   # eq. 7.70 / 7.85 / 7.96
        else:
            Qs = np.repeat(q[None, :], S, axis=0)
            Ws = np.repeat(w[None, :], S, axis=0)
        _, Qd, phib = layout_transition(dyn, L, bias, facets, w, dt) if dt != 0.0 else \
            (np.eye(nx), np.zeros((nx, nx)), np.ones(nb) if nb else None)
        cols = []
        if na:
            cols += [grp_rel(Qs, Qs[0]), Ws]                         # eq. 7.71
        if nb:
            cols.append((b + chi[:, L.ib]) * phib)
        if nz:
            cols.append(z + chi[:, L.iz])
        X = np.hstack(cols)
        xm = wts.wm @ X                                              # eq. 7.72
        D = X - xm
        Pm = (D * wts.wc[:, None]).T @ D                             # eq. 7.73
        if na:                        # the extra states' noise is additive (docstring)
            Pm[6:, 6:] += Qd[6:, 6:]
        else:
            Pm += Qd
        q0 = Qs[0]
        post = (_measurement(k, y, R, Qs, chi, D, xm, Pm, wts, L, nq, controlled, bias,
                             facets, b, z, m, gate, rec) if use else None)
        x, Pk = (xm, Pm) if post is None else post   # no update: the time update stands
        if na:
            q = apply_grp(x[None, :3], q0)[0]        # eq. 7.74 / eq. 7.82
            w = x[3:6].copy()
        b, z, P = x[L.ib].copy(), x[L.iz].copy(), 0.5 * (Pk + Pk.T)
        store_epoch(rec, k, L, q, w, b, z, P, hists)
    est = gate.finish(rec.finish(time.perf_counter() - t0))
    est.meta["variant"] = "thesis"
    return attach_histories(est, L, bias, facets, hists)


def _measurement(k, y, R, Qs, chi, D, xm, Pm, wts, L, nq, controlled, bias, facets, b, z, m,
                 gate, rec):
    """Measurement update of epoch k from the propagated points (eq. 7.75–7.81; controlled: ζ
    columns perturb the attitude first, eq. 7.87) → ``(x⁺, P⁺)``, or None when the epoch gives
    no update (a point predicts no light, a gate rejects it, P_yy not positive; flagged)."""
    nx = L.nx
    Qm = Qs
    if L.na and nq and controlled:
        Qm = perturb_rotvec_nb(np.ascontiguousarray(Qs),
                                 np.ascontiguousarray(chi[:, nx:nx + 3]))        # eq. 7.87
    Y = facets.magnitudes(m, Qm, z + chi[:, L.iz], k) if L.nz else m.predict_q(Qm, k)
    if not np.all(np.isfinite(Y)):
        rec.flags[k] |= FLAG_INVISIBLE
        return None
    if L.nb:
        s = int(bias.site[k])
        Y = Y + b[s] + chi[:, L.na + s]
    Y = Y + chi[:, -1]                                           # ν columns (eq. 7.75)
    ym = float(wts.wm @ Y)                                       # eq. 7.76
    dY = Y - ym
    Pyy = float(wts.wc @ (dY * dY))                              # eq. 7.77
    Pxy = (D * wts.wc[:, None]).T @ dY                           # eq. 7.78
    nu = float(y - ym)
    Rg = gate.check(k, nu, Pyy, R, rec)      # mode off (thesis): records the NIS only
    if Rg is None:                           # rejected by an explicitly given gate
        return None
    Pyy += Rg - R                            # inflated noise (R' ≥ R), else no change
    if not (Pyy > 0.0 and np.isfinite(Pyy)):
        rec.flags[k] |= FLAG_REFUSED
        return None
    Kg = Pxy / Pyy                                               # eq. 7.79
    rec.innovation(k, nu, Pyy)
    return xm + Kg * nu, Pm - Pyy * np.outer(Kg, Kg)             # eq. 7.80–7.81


def _linear_step(p, L, bias, facets, q, w, b, P, dt):
    """A refused factorisation: propagate the mean and Φ P Φᵀ + Q_d (flagged by the caller)."""
    if dt == 0.0:
        return q, w, b, P
    Phi, Qd, phib = layout_transition(p.dynamics, L, bias, facets, w, dt)
    if L.na:
        Qn, Wn = p.dynamics.propagate(q[None, :], w[None, :], dt)
        q, w = Qn[0], Wn[0]
    if L.nb:
        b = phib * b
    Pn = Phi @ P @ Phi.T + Qd
    return q, w, b, 0.5 * (Pn + Pn.T)
