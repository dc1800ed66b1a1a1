"""Pieces shared by the three attitude filters: the problem definition and the run record."""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from ..core.rotations import from_grp_rel_nb, grp_rel_nb
from ..estimation.consistency import NISDivergenceDetector
from .result import FLAG_COLLAPSE, FLAG_NIS, FLAG_REFUSED, Estimate

GRP_A = 1.0
GRP_F = 4.0


@dataclass
class FilterProblem:
    """Everything a filter needs: measurement model, dynamics and initial estimate.

    Attributes
    ----------
    model : MagnitudeModel
    dynamics : ControlledDynamics or UncontrolledDynamics
    q0 : (4,) initial attitude estimate (inertial→body) at ``model.t[0]``
    omega0 : (3,) initial rate estimate, rad/s, body axes
    P0 : (6,6) initial error covariance of [δθ (rad), δω (rad/s)]
    truth_q, truth_omega : (N,4), (N,3) or None
    meta : dict of settings recorded in the Estimate
    attitude_known : bool
        "Attitude known" mode (Bernard §10.7 parameter-only runs): the Kalman filters hold
        q, ω at the truth of every epoch (``truth_q``, ``truth_omega`` required) and estimate
        only the extra states (site biases and/or Model 3 facet parameters); the attitude/rate
        error states are dropped, so the Estimate's attitude covariance is zero.
    """

    model: object
    dynamics: object
    q0: np.ndarray
    omega0: np.ndarray
    P0: np.ndarray
    truth_q: np.ndarray | None = None
    truth_omega: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    attitude_known: bool = False

    def __post_init__(self):
        self.q0 = np.asarray(self.q0, float).reshape(4)
        self.q0 = self.q0 / np.linalg.norm(self.q0)
        self.omega0 = np.asarray(self.omega0, float).reshape(3)
        self.P0 = np.asarray(self.P0, float).reshape(6, 6)
        if not (np.all(np.isfinite(self.q0)) and np.all(np.isfinite(self.omega0))
                and np.all(np.isfinite(self.P0))):
            raise ValueError("initial estimate contains NaN or inf")
        try:
            np.linalg.cholesky(self.P0)
        except np.linalg.LinAlgError:
            raise ValueError("initial covariance P0 is not positive definite") from None
        if self.attitude_known and (self.truth_q is None or self.truth_omega is None):
            raise ValueError("attitude_known needs truth_q and truth_omega")

    @property
    def n(self) -> int:
        """Number of epochs."""
        return len(self.model)

    def random_walk_zeta(self) -> bool:
        """True when the ACS noise ζ is a random walk of the attitude (process noise)."""
        d = self.dynamics
        return d.acs_sigma > 0.0 and d.acs_mode == "random_walk"

    def jitter_zeta(self) -> bool:
        """True when ζ is measurement-time jitter about the nominal profile (eq. 7.27)."""
        d = self.dynamics
        return d.acs_sigma > 0.0 and d.acs_mode == "jitter"


class Recorder:
    """Collects per-epoch results and builds the :class:`Estimate`."""

    def __init__(self, problem: FilterProblem, method: str, nis_window=10, nis_prob=0.999):
        N = problem.n
        self.p = problem
        self.method = method
        self.q = np.full((N, 4), np.nan)
        self.w = np.full((N, 3), np.nan)
        self.P = np.full((N, 6, 6), np.nan)
        self.nu = np.full(N, np.nan)
        self.S = np.full(N, np.nan)
        self.neff = np.full(N, np.nan)
        self.flags = np.zeros(N, dtype=np.int64)
        self.nis = np.full(N, np.nan)
        self.skipped_nan = 0
        self.det = NISDivergenceDetector(1, nis_window, nis_prob)
        self.reason = ""

    def innovation(self, k, nu, S):
        """Record the innovation ν (mag) and its variance S (mag²) at epoch k."""
        self.nu[k] = nu
        self.S[k] = S
        if np.isfinite(nu) and S > 0:
            self.nis[k] = nu * nu / S
            if self.det.update(self.nis[k]):
                self.flags[k] |= FLAG_NIS

    def store(self, k, q, w, P):
        """Record the posterior of epoch k."""
        q = np.asarray(q, float)
        self.q[k] = q / np.linalg.norm(q)
        self.w[k] = w
        self.P[k] = 0.5 * (P + P.T)

    def finish(self, runtime_s) -> Estimate:
        """Build the Estimate (with truth comparison when the problem has truth)."""
        p = self.p
        d = np.clip(np.diagonal(self.P, axis1=1, axis2=2), 0.0, None)
        att_var = d[:, :3].copy()
        if p.jitter_zeta():
            att_var += p.dynamics.acs_sigma ** 2
        diverged = False
        reasons = []
        last_upd = np.flatnonzero(np.isfinite(self.nis))
        if last_upd.size and (self.flags[last_upd[-1]] & FLAG_NIS):
            diverged = True
            reasons.append("sliding-window NIS above its 99.9% bound at the last update")
        if np.any(self.flags & FLAG_COLLAPSE):
            diverged = True
            reasons.append(f"particle weights collapsed at {int(np.sum(self.flags & FLAG_COLLAPSE > 0))} "
                           "epoch(s)")
        if last_upd.size == 0:
            diverged = True
            reasons.append("no measurement update at all (every prediction invisible or refused)")
        nref = int(np.sum((self.flags & FLAG_REFUSED) > 0))
        nupd = int(np.sum(np.isfinite(p.model.y)))
        if nref and nref >= max(1, nupd // 2):
            diverged = True
            reasons.append(f"{nref} of {nupd} updates refused (numerical failure)")
        # Kalman filters: a gap the attitude cannot be carried across — the 1σ rate
        # uncertainty before it, times its length, is more than half a turn — after which
        # the attitude 1σ is under 90°: one magnitude cannot determine an attitude that is
        # unknown, so the filter claims what it cannot know (a 10⁸ s gap before the last
        # epochs used to end the MEKF 158° off with no flag). The particle filter is not
        # flagged: its cloud spreads over the gap and re-acquires, or not, on later evidence.
        t = np.asarray(p.model.t, float)
        if t.size > 1 and self.method in ("mekf", "ukf"):
            spread = np.sqrt(d[:-1, 3:].max(axis=1)) * np.diff(t)
            after = np.sqrt(att_var[1:].max(axis=1))
            lost = np.flatnonzero((spread > np.pi) & (after < 0.5 * np.pi))
            if lost.size:
                k = int(lost[0])
                diverged = True
                reasons.append(f"attitude lost across a {t[k + 1] - t[k]:.3g} s gap after epoch "
                               f"{k} (1-sigma rate uncertainty x gap = {np.degrees(spread[k]):.3g} "
                               f"deg, attitude 1-sigma after it {np.degrees(after[k]):.3g} deg)")
        if not (np.all(np.isfinite(self.q)) and np.all(np.isfinite(self.w))
                and np.all(np.isfinite(self.P))):
            # never expected (every step guards), but never return silent NaN either
            diverged = True
            reasons.append("non-finite estimate")
        est = Estimate(
            method=self.method, t=p.model.t.copy(), q=self.q, omega_rad_s=self.w, cov=self.P,
            att_sigma_deg=np.degrees(np.sqrt(att_var)), omega_sigma_rad_s=np.sqrt(d[:, 3:]),
            innovations=self.nu, innovation_var=self.S, n_eff=self.neff, flags=self.flags,
            skipped_nan=int(self.skipped_nan), diverged=diverged,
            divergence_reason="; ".join(reasons), runtime_s=float(runtime_s), meta=dict(p.meta))
        if p.truth_q is not None and p.truth_omega is not None:
            extra = p.dynamics.acs_sigma ** 2 if p.jitter_zeta() else 0.0
            est.attach_truth(p.truth_q, p.truth_omega, extra_att_var=extra)
        return est


def grp_to_dq(p):
    """Quaternions (S,4) of GRP error vectors p (S,3) (a = 1, f = 4)."""
    P = np.ascontiguousarray(np.asarray(p, float).reshape(-1, 3))
    ident = np.array([1.0, 0.0, 0.0, 0.0])
    return from_grp_rel_nb(P, ident, GRP_A, GRP_F)


def apply_grp(p, qref):
    """``grp2q(p_i) ⊗ qref`` for p (S,3) → (S,4)."""
    P = np.ascontiguousarray(np.asarray(p, float).reshape(-1, 3))
    return from_grp_rel_nb(P, np.ascontiguousarray(qref, dtype=float), GRP_A, GRP_F)


def grp_rel(Q, qref):
    """GRP (S,3) of ``Q_i ⊗ qref⁻¹`` (sign with δq1 ≥ 0)."""
    return grp_rel_nb(np.ascontiguousarray(Q, dtype=float),
                        np.ascontiguousarray(qref, dtype=float), GRP_A, GRP_F)


def psd_sqrt(C):
    """L (n, r) with L Lᵀ = C for a symmetric positive semi-definite C (eigen-decomposition).

    Only the r columns of eigenvalues above 1e-15 × the largest are kept (r = 0 for C = 0), so
    a noise sample ``z Lᵀ`` needs r, not n, standard normals per row.
    """
    C = 0.5 * (np.asarray(C, float) + np.asarray(C, float).T)
    if not np.all(np.isfinite(C)):
        raise ValueError("covariance contains NaN or inf")
    ev, V = np.linalg.eigh(C)
    top = float(ev.max()) if ev.size else 0.0
    keep = ev > 1e-15 * top if top > 0 else np.zeros(ev.shape, bool)
    return V[:, keep] * np.sqrt(ev[keep])[None, :]


class single_thread:
    """Context manager running numba parallel kernels on one thread.

    The Kalman filters evaluate kernels on 1–20 states per call; waking a thread pool for that
    costs far more than the work (tens of ms per call on a loaded 2-core machine), so they run
    single-threaded. The previous thread count is restored on exit.
    """

    def __enter__(self):
        self._n = numba.get_num_threads()
        numba.set_num_threads(1)
        return self

    def __exit__(self, *exc):
        numba.set_num_threads(self._n)
        return False


class StateLayout:
    """Index layout of the Kalman filters' error state ``[δθ, δω | b_1 … b_S | z_1 … z_D]``.

    ``na`` = 6 (attitude and rate estimated) or 0 (attitude known, ``FilterProblem.
    attitude_known``); ``nb`` site biases (:class:`~lightcurve.filters.reflection.SiteBias`);
    ``nz`` Model 3 facet states (:class:`~lightcurve.filters.facet_states.FacetParameterStates`).
    Slices ``ia``, ``ib``, ``iz``; total ``nx``.
    """

    def __init__(self, attitude: bool, bias=None, facets=None):
        self.na = 6 if attitude else 0
        self.nb = 0 if bias is None else bias.n_sites
        self.nz = 0 if facets is None else facets.dim
        self.nx = self.na + self.nb + self.nz
        self.ia = slice(0, self.na)
        self.ib = slice(self.na, self.na + self.nb)
        self.iz = slice(self.na + self.nb, self.nx)


def initial_state_ext(p: "FilterProblem", bias=None, facets=None):
    """Initial state of the Kalman filters with optional bias and Model 3 states.

    Returns ``(layout, q, ω, b, z, P)``: ``P`` block diagonal (``p.P0`` unless the attitude is
    known, ``diag(bias.var0)``, ``facets.P0``), ``b`` zeros, ``z`` the prior centre
    ``facets.z0``; with a known attitude ``q, ω`` are the truth at the first epoch.
    """
    L = StateLayout(not p.attitude_known, bias, facets)
    if p.attitude_known:
        q, w = truth_state(p, 0)
    else:
        q, w = p.q0.copy(), p.omega0.copy()
    P = np.zeros((L.nx, L.nx))
    if L.na:
        P[:6, :6] = p.P0
    if L.nb:
        P[L.ib, L.ib] = np.diag(bias.var0)
    if L.nz:
        P[L.iz, L.iz] = facets.P0
    b = np.zeros(L.nb)
    z = facets.z0.copy() if L.nz else np.zeros(0)
    return L, q, w, b, z, P


def reflection_histories(n, nb, nz):
    """NaN-filled per-epoch histories of the reflection states for n epochs.

    Returns ``(b, b_sigma, z, z_cov)``: (n, nb) site biases and their 1σ, mag; (n, nz) Model 3
    states and (n, nz, nz) their covariance (unbounded z units); None for an absent block.
    """
    b = np.full((n, nb), np.nan) if nb else None
    bs = np.full((n, nb), np.nan) if nb else None
    z = np.full((n, nz), np.nan) if nz else None
    zc = np.full((n, nz, nz), np.nan) if nz else None
    return b, bs, z, zc


def store_epoch(rec, k, L: "StateLayout", q, w, b, z, P, hists) -> None:
    """Record epoch k of a Kalman run: q, ω and their 6×6 covariance in ``rec`` (zeros when
    the attitude is known), the site biases with their 1σ and the Model 3 states with their
    covariance in ``hists`` (:func:`reflection_histories`)."""
    b_hist, bs_hist, z_hist, zc_hist = hists
    rec.store(k, q, w, P[:6, :6] if L.na else np.zeros((6, 6)))
    if L.nb:
        b_hist[k] = b
        bs_hist[k] = np.sqrt(np.clip(np.diag(P)[L.ib], 0.0, None))
    if L.nz:
        z_hist[k] = z
        zc_hist[k] = P[L.iz, L.iz]


def attach_histories(est, L: "StateLayout", bias, facets, hists):
    """``est`` with the histories of :func:`store_epoch` attached (biases, Model 3 states) and
    ``meta["attitude"] = "truth"`` when the attitude was known."""
    b_hist, bs_hist, z_hist, zc_hist = hists
    if L.nb:
        attach_bias(est, bias, b_hist, bs_hist)
    if L.nz:
        attach_facets(est, facets, z_hist, zc_hist)
    if not L.na:
        est.meta["attitude"] = "truth"
    return est


def truth_state(p: "FilterProblem", k):
    """The file's truth ``(q (4,), ω (3,))`` at epoch k (attitude-known mode)."""
    q = np.asarray(p.truth_q[k], float)
    return q / np.linalg.norm(q), np.asarray(p.truth_omega[k], float).copy()


def layout_transition(dyn, L: StateLayout, bias, facets, w, dt):
    """Error-state ``(Φ, Q_d, φ_b)`` over dt s for a :class:`StateLayout`: the attitude/rate
    block from ``dyn.transition`` (absent when the attitude is known), the bias block
    ``diag(φ_b), diag(q_b)``, the Model 3 block ``Φ = I`` and ``facets.transition(dt)``
    (eq. 8.39)."""
    Phi, Qd = np.zeros((L.nx, L.nx)), np.zeros((L.nx, L.nx))
    if L.na:
        Phi[:6, :6], Qd[:6, :6] = dyn.transition(w, dt)
    phib = None
    if L.nb:
        phib, qb = bias.transition(dt, w)
        Phi[L.ib, L.ib], Qd[L.ib, L.ib] = np.diag(phib), np.diag(qb)
    if L.nz:
        Phi[L.iz, L.iz], Qd[L.iz, L.iz] = facets.transition(dt)
    return Phi, Qd, phib


def attach_facets(est, facets, z_hist, z_cov_hist) -> None:
    """Store the Model 3 history in an Estimate: ``refl_z`` / ``refl_z_sigma`` (N,D) in the
    unconstrained coordinates, ``refl_p`` / ``refl_p_sigma`` (N,D) in physical units (1σ by
    the first-order map ``|dp/dz| σ_z``), the state names, and the final values in
    ``meta["reflection"]`` (merged with a bias model's entry when both are present)."""
    zs = np.sqrt(np.clip(np.diagonal(z_cov_hist, axis1=1, axis2=2), 0.0, None))
    est.refl_names = list(facets.names)
    est.refl_z, est.refl_z_sigma = z_hist, zs
    est.refl_p = facets.to_p(z_hist)
    est.refl_p_sigma = facets.sigma_p(z_hist, z_cov_hist)
    last = np.flatnonzero(np.all(np.isfinite(z_hist), axis=1))
    k = int(last[-1]) if last.size else len(z_hist) - 1
    d = dict(facets.describe(), p_final=est.refl_p[k].tolist(),
             p_sigma_final=est.refl_p_sigma[k].tolist(), z_final=z_hist[k].tolist(),
             z_sigma_final=zs[k].tolist())
    prev = est.meta.get("reflection")
    if isinstance(prev, dict) and prev.get("model") not in (None, "model3"):
        d = dict(prev, facet_states=d)
    est.meta["reflection"] = d
    est.meta["reflection_names"] = list(facets.names)


def attach_bias(est, bias, b_hist, bs_hist) -> None:
    """Store the site-bias history (mag) and its 1σ in an Estimate and its metadata."""
    est.bias, est.bias_sigma = b_hist, bs_hist
    est.meta["reflection"] = dict(bias.describe(), bias_final_mag=b_hist[-1].tolist(),
                                  bias_sigma_final_mag=bs_hist[-1].tolist())
