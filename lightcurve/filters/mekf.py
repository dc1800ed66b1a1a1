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
   Model 3 (``facets``, :mod:`lightcurve.filters.facet_states`): the facet parameters'
   unconstrained coordinates z are appended, ``[δθ, δω, b…, z]``; ``ŷ = m(q̂, p(ẑ))``,
   ``H_z = ∂m/∂p · dp/dz`` (analytic partials), constant dynamics (``Φ_z = I``, eq. 8.39);
   ``est.refl_z``/``refl_p`` (N,D) with 1σ hold the history. With
   ``problem.attitude_known`` (§10.7) q̂, ω̂ are the truth of every epoch and only b, z are
   estimated.
   A refused update (S not positive definite, non-finite values) keeps the prior and sets
   :data:`~lightcurve.filters.result.FLAG_REFUSED`; an estimate that predicts no reflected
   light (m = +inf) skips the update with :data:`~lightcurve.filters.result.FLAG_INVISIBLE`.
   Screening (:mod:`lightcurve.filters.gating`): epochs with the object unlit or below the
   horizon are skipped, and a magnitude whose ``ν²/S`` (``S = H P⁻ Hᵀ + R``) exceeds the χ²
   gate is rejected (or used with inflated R), flagged and counted.

Implementation: the scalar Joseph update is the core's O(n²) kernel
(:func:`lightcurve.core.kalman.joseph_scalar_nb`), and with the analytic Jacobian the magnitude
and all its partials come from one numba pass over the facets
(:func:`lightcurve.core.photometry.magnitude_partials_q_nb`,
:func:`lightcurve.filters.facet_states.partials_z_nb`) when every facet has analytic partials —
no shape copy per epoch.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.kalman import UPDATE_OK, joseph_scalar_nb
from ..core.photometry import magnitude_partials_q_nb
from ..core.rotations import from_grp_rel_nb, normalize_into_nb, perturb_rotvec_nb, qmul_nb
from ..photometry.partials import kernel_capable
from .config import MEKFConfig
from ._common import GRP_A, GRP_F, FilterProblem, single_thread
from .driver import StepBase, run_kalman
from .result import FLAG_INVISIBLE, FLAG_REFUSED, Estimate

__all__ = ["run_mekf"]


def _reset(q, dth, error):
    """``normalise(δq(δθ⁺) ⊗ q)`` (Bernard eq. 3.20): δq the GRP quaternion of δθ⁺
    (eq. 3.29–3.30, a = 1, f = 4) or, for ``small_angle``, ``normalise([1, δθ⁺/2])``."""
    q = np.ascontiguousarray(q, dtype=float)
    if error == "grp":
        return from_grp_rel_nb(np.ascontiguousarray(dth, dtype=float).reshape(1, 3), q,
                               GRP_A, GRP_F)[0]
    dq = np.concatenate([[1.0], 0.5 * np.asarray(dth, float)])
    normalize_into_nb(dq, False)
    qn = qmul_nb(dq, q)
    normalize_into_nb(qn, False)
    return qn


def run_mekf(problem: FilterProblem, config: MEKFConfig | None = None, *, error=None,
             jacobian=None, bias=None, facets=None) -> Estimate:
    """Run the MEKF over every epoch of ``problem`` (module docstring) → :class:`Estimate`.

    Parameters
    ----------
    problem : FilterProblem
    config : :class:`~lightcurve.filters.config.MEKFConfig`, optional (default settings)
    error, jacobian : optional overrides of ``config.error`` ({"grp", "small_angle"}: how the
        error rotation ``δθ⁺`` is mapped back to a quaternion at the reset) and
        ``config.jacobian`` ({"analytic", "numeric"}: ``∂m/∂δθ`` analytic or by central
        differences).
    bias : :class:`lightcurve.filters.reflection.SiteBias` or None
        Per-site reflection-bias states (module docstring); None = attitude and rate only.
    facets : :class:`lightcurve.filters.facet_states.FacetParameterStates` or None
        Model 3 facet-parameter states z appended after the biases (module docstring).
    """
    config = MEKFConfig.resolve(config, error=error, jacobian=jacobian)
    problem.meta.setdefault("variant", config.variant)
    with single_thread():
        return run_kalman(problem, _MEKFStep(problem, config.error, config.jacobian, bias,
                                             facets), bias, facets)


class _Photometry:
    """The shape's plain kernel arrays, packed once per run (attitude-only analytic path)."""

    def __init__(self, model, jacobian):
        shape = model.shape
        ids = np.ascontiguousarray(shape.model_ids, dtype=np.int64)
        self.ok = jacobian == "analytic" and kernel_capable(ids)
        n, a, _, prm = shape.kernel_arrays()
        self.normals = np.ascontiguousarray(n, dtype=float)
        self.areas = np.ascontiguousarray(a, dtype=float)
        self.ids = ids
        self.params = np.ascontiguousarray(prm, dtype=float)
        F = self.areas.shape[0]
        self.work = tuple(np.empty(F) for _ in range(4))   # ∂m/∂A, ∂m/∂ξ, ∂m/∂a, ∂m/∂m


class _MEKFStep(StepBase):
    """The MEKF's time and measurement updates (module docstring) for
    :func:`lightcurve.filters.driver.run_kalman`."""

    method = "mekf"
    gate_auto = "inflate"

    def __init__(self, problem, error, jacobian, bias, facets):
        super().__init__(problem, bias, facets)
        self.error = error
        self.jacobian = jacobian
        self.ph = _Photometry(problem.model, jacobian)

    def predict(self, x, k, dt, Phi, Qd, phib, rec):
        L = x.layout
        if L.nb:
            x.b = phib * x.b
        if L.na:
            Qn, Wn = self.p.dynamics.propagate(x.q[None, :], x.w[None, :], dt)
            x.q, x.w = Qn[0], Wn[0]
        x.P = Phi @ x.P @ Phi.T + Qd

    def update(self, x, k, y, rec):
        p, m, L = self.p, self.p.model, x.layout
        na, nb, nz, nx = L.na, L.nb, L.nz, L.nx
        yhat, Hth, Hz = _predict(m, self.facets, x.q, x.z, k, self.jacobian, self.ph)
        if not np.isfinite(yhat) or not np.all(np.isfinite(Hth)) or not np.all(np.isfinite(Hz)):
            rec.flags[k] |= FLAG_INVISIBLE
            return
        H = np.zeros((1, nx))
        if na:
            H[0, :3] = Hth
        if nb:
            s = int(self.bias.site[k])
            H[0, na + s] = 1.0
            yhat += float(x.b[s])
        if nz:
            H[0, L.iz] = Hz
        R = m.sigma[k] ** 2
        if na and p.jitter_zeta():
            R = R + float(Hth @ self.zc @ Hth)
        # innovation gate: None = outlier rejected (flagged; prior kept)
        R = rec.gate.check(k, y - yhat, float(H[0] @ x.P @ H[0]) + R, R, rec)
        if R is None:
            return
        dx, Pn, nu, S, ok = _update(x.P, H[0], R, y, yhat)
        rec.innovation(k, nu, S)
        if not ok:
            rec.flags[k] |= FLAG_REFUSED
            return
        if na:
            x.q = _reset(x.q, dx[:3], self.error)
            x.w = x.w + dx[3:6]
        x.b = x.b + dx[L.ib]
        x.z = x.z + dx[L.iz]
        x.P = Pn


def _update(P, h, R, y, yhat):
    """Scalar Joseph update (:func:`lightcurve.core.kalman.joseph_scalar_nb`) →
    ``(δx⁺, P⁺, ν, S, ok)``."""
    n = P.shape[0]
    dx = np.empty(n)
    Pn = np.empty((n, n))
    nu = float(y - yhat)
    S, status = joseph_scalar_nb(np.ascontiguousarray(P), np.ascontiguousarray(h, dtype=float),
                                 float(R), nu, dx, Pn)
    return dx, Pn, nu, float(S), status == UPDATE_OK


def _predict(m, facets, q, z, k, jacobian, ph=None, h=1e-6):
    """``(ŷ, ∂m/∂δθ (3,), ∂m/∂z (D,))`` at the attitude q and Model 3 state z (D = 0 without
    facet states). Analytic partials (one numba pass over the facets when ``ph`` — a
    :class:`_Photometry` — allows it), or central differences (step h rad / h in z)."""
    if facets is None and ph is not None and ph.ok:
        dA, dxi, da, dmm = ph.work
        yhat, tx, ty, tz = magnitude_partials_q_nb(
            np.ascontiguousarray(q, dtype=float), m.s_eci[k], m.o_eci[k], ph.normals, ph.areas,
            ph.ids, ph.params, float(m.offset[k]), dA, dxi, da, dmm)
        if not math.isfinite(yhat):
            return yhat, np.full(3, np.nan), np.zeros(0)
        return yhat, np.array([tx, ty, tz]), np.zeros(0)
    if facets is None:
        yhat = float(m.predict_q(q[None, :], k)[0])
        Hth = m.jacobian_theta(q, k, method=jacobian) if np.isfinite(yhat) else np.full(3, np.nan)
        return yhat, Hth, np.zeros(0)
    if jacobian == "analytic":
        return facets.partials(m, q, z, k)
    yhat = float(facets.magnitudes(m, q[None, :], z, k)[0])
    d = np.concatenate([h * np.eye(3), -h * np.eye(3)])
    Qp = perturb_rotvec_nb(np.ascontiguousarray(np.tile(q, (6, 1))), d)
    mq = facets.magnitudes(m, Qp, z, k)
    E = h * np.eye(facets.dim)
    Zp = np.concatenate([z + E, z - E])
    mz = facets.magnitudes(m, np.tile(q, (2 * facets.dim, 1)), Zp, k)
    return yhat, (mq[:3] - mq[3:]) / (2 * h), (mz[:facets.dim] - mz[facets.dim:]) / (2 * h)
