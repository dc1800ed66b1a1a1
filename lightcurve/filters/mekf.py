"""Multiplicative extended Kalman filter (MEKF) on magnitudes (Bernard 2021 tables 7.1, 7.2).

Global state ``[q̂, ω̂]`` (inertial→body quaternion, scalar first; body rate rad/s), error state
``δx = [δθ, δω]`` with ``q_true = δq(δθ) ⊗ q̂`` (module :mod:`lightcurve.filters.models`).

Per epoch k (times sorted as in the lightcurve; two sites may share a time, Δt = 0):

1. Propagation (k > 0): ``q̂, ω̂`` with the nonlinear model (exact constant-rate step or
   torque-free RK4); ``P⁻ = Φ P Φᵀ + Q_d`` with ``Φ = exp(F Δt)`` (eq. 7.24 / 7.37) and ``Q_d``
   the discrete process noise (η for the uncontrolled model, optional pseudo-noise).
   Controlled, ``acs_mode="random_walk"``: at each new measurement time ``P_θθ += σ_ζ² I``.
2. Update (finite magnitude only; NaN rows are skipped and counted): predicted magnitude
   ``ŷ = m(q̂)``, ``H = [∂m/∂δθ, 0₁ₓ₃]`` (analytic photometry partials or central differences),
   ``R = σ_k²`` (+ ``H_θ σ_ζ² H_θᵀ`` for the controlled "jitter" model, eq. 7.27), Joseph-form
   update of ``δx`` from zero (:func:`lightcurve.estimation.joseph_update`), then the reset
   ``q̂ ← δq(δθ⁺) ⊗ q̂`` (GRP: ``δq = grp2q(δθ⁺)``, a = 1, f = 4; small angle:
   ``δq = normalise([1, δθ⁺/2])``), ``ω̂ ← ω̂ + δω⁺``.
   With a reflection bias model (``bias``, :mod:`lightcurve.filters.reflection`) the error
   state is ``[δθ, δω, b_1 … b_S]``: ``ŷ = m(q̂) + b̂_site``, ``H = [∂m/∂δθ, 0, e_site]``, the
   bias block propagates with its own diagonal ``Φ_b, Q_b``; the Estimate's covariance keeps
   the 6×6 attitude/rate block and ``est.bias`` / ``est.bias_sigma`` (N,S) hold the biases.
   A refused update (S not positive definite, non-finite values) keeps the prior and sets
   :data:`~lightcurve.filters.result.FLAG_REFUSED`; an estimate that predicts no reflected
   light (m = +inf) skips the update with :data:`~lightcurve.filters.result.FLAG_INVISIBLE`.
"""

from __future__ import annotations

import time

import numpy as np

from .. import rotations as rot
from ..estimation.kalman import joseph_update
from ._common import (FilterProblem, Recorder, attach_bias, augmented_transition, grp_to_dq,
                      initial_state, single_thread)
from .result import FLAG_INVISIBLE, FLAG_NAN, FLAG_REFUSED, Estimate

__all__ = ["run_mekf"]


def _reset(q, dth, error):
    if error == "grp":
        dq = grp_to_dq(dth)[0]
    else:
        dq = np.concatenate([[1.0], 0.5 * np.asarray(dth, float)])
        dq /= np.linalg.norm(dq)
    qn = rot.quat_mult(dq, q)
    return qn / np.linalg.norm(qn)


def run_mekf(problem: FilterProblem, *, error="grp", jacobian="analytic", bias=None) -> Estimate:
    """Run the MEKF over every epoch of ``problem`` (module docstring) → :class:`Estimate`.

    Parameters
    ----------
    problem : FilterProblem
    error : {"grp", "small_angle"}
        How the error rotation ``δθ⁺`` is mapped back to a quaternion at the reset.
    jacobian : {"analytic", "numeric"}
        ``∂m/∂δθ`` from :func:`lightcurve.photometry.magnitude_partials` or central differences.
    bias : :class:`lightcurve.filters.reflection.SiteBias` or None
        Per-site reflection-bias states (module docstring); None = attitude and rate only.
    """
    if error not in ("grp", "small_angle"):
        raise ValueError(f"error must be 'grp' or 'small_angle', got {error!r}")
    if jacobian not in ("analytic", "numeric"):
        raise ValueError(f"jacobian must be 'analytic' or 'numeric', got {jacobian!r}")
    with single_thread():
        return _run(problem, error, jacobian, bias)


def _run(problem, error, jacobian, bias=None):
    t0 = time.perf_counter()
    p = problem
    m = p.model
    dyn = p.dynamics
    rec = Recorder(p, "mekf")
    q, w, nb, nx, P, b, b_hist, bs_hist = initial_state(p, bias)
    zc = dyn.zeta_cov
    for k in range(p.n):
        if k > 0:
            dt = float(m.t[k] - m.t[k - 1])
            if dt != 0.0:
                Phi, Qd, phib = augmented_transition(dyn, bias, w, dt, nx)
                if nb:
                    b = phib * b
                Qn, Wn = dyn.propagate(q[None, :], w[None, :], dt)
                q, w = Qn[0], Wn[0]
                P = Phi @ P @ Phi.T + Qd
                if p.random_walk_zeta():
                    P[:3, :3] += zc
                P = 0.5 * (P + P.T)
        y = m.y[k]
        if not np.isfinite(y):
            rec.flags[k] |= FLAG_NAN
            rec.skipped_nan += 1
        else:
            yhat = float(m.predict_q(q[None, :], k)[0])
            Hth = m.jacobian_theta(q, k, method=jacobian) if np.isfinite(yhat) else None
            if not np.isfinite(yhat) or not np.all(np.isfinite(Hth)):
                rec.flags[k] |= FLAG_INVISIBLE
            else:
                H = np.zeros((1, nx))
                H[0, :3] = Hth
                if nb:
                    s = int(bias.site[k])
                    H[0, 6 + s] = 1.0
                    yhat += float(b[s])
                R = m.sigma[k] ** 2
                if p.jitter_zeta():
                    R = R + float(Hth @ zc @ Hth)
                dx, Pn, info = joseph_update(np.zeros(nx), P, y, H, R, h=yhat)
                rec.innovation(k, float(info.innovation[0]), float(info.S[0, 0]))
                if info.ok:
                    q = _reset(q, dx[:3], error)
                    w = w + dx[3:6]
                    b = b + dx[6:]
                    P = Pn
                else:
                    rec.flags[k] |= FLAG_REFUSED
        rec.store(k, q, w, P[:6, :6])
        if nb:
            b_hist[k] = b
            bs_hist[k] = np.sqrt(np.clip(np.diag(P)[6:], 0.0, None))
    est = rec.finish(time.perf_counter() - t0)
    if nb:
        attach_bias(est, bias, b_hist, bs_hist)
    return est
