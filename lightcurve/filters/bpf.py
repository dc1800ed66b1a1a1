"""Bootstrap particle filter (BPF) on magnitudes, numba kernels (Bernard 2021 tables 7.7–7.11).

Particles ``(q_i, ω_i)``: inertial→body quaternions (scalar first) and body rates (rad/s).

1. Initialisation (table 7.7): ``[δp_i, δω_i] ~ N(0, P₀)`` with δp a GRP (a = 1, f = 4);
   ``q_i = grp2q(δp_i) ⊗ q̂₀``, ``ω_i = ω̂₀ + δω_i``; log weights ``−log N``.
2. Propagation with the truth dynamics (table 7.8): exact constant-rate step (controlled) or
   torque-free RK4 (uncontrolled), then a process-noise sample ``[δθ, δω] ~ N(0, Q_d)``
   (η, pseudo-noise) and, for the controlled random-walk ACS model, ``ζ_i ~ N(0, σ_ζ² I)``
   applied as ``q_i ← exp(ζ_i) ⊗ q_i`` at every new measurement time. For the "jitter" ACS
   model ζ_i perturbs only the attitude used to predict the measurement.
3. Weights (table 7.10): ``log w_i += −½ ((y − m(q_i))/σ)²`` (m = +inf → −inf), normalised
   with log-sum-exp; ``N_eff = 1/Σ w_i²``.
3b. Progressive correction (Oudjane & Musso 2000; an addition to the thesis's plain
   bootstrap filter, on by default, ``progressive=False`` switches it off): when the full
   likelihood would leave ``N_eff < ess_threshold · N`` — as at the first measurements from a
   60° prior, where one measurement of σ ≈ 0.05 mag leaves a handful of the 10⁴ particles —
   the likelihood is applied as ``L^φ₁ L^φ₂ … (Σφ = 1)``: each φ is the largest keeping
   ``N_eff`` at the threshold (bisection), followed by resampling and roughening and a new
   prediction of the moved particles. The posterior is the same; the cloud is not collapsed
   onto the few particles that happened to lie near the likelihood's ridge. If every weight is zero the weights are reset to
   uniform and the epoch is flagged (:data:`~lightcurve.filters.result.FLAG_COLLAPSE`; the run
   is then reported as diverged).
4. Estimate (eq. 7.100–7.105): weighted GRP mean about a reference attitude (the heaviest
   particle refined once by the weighted GRP mean), ``q̂ = grp2q(δp̄) ⊗ q_ref``,
   ``ω̂ = Σ w ω``, covariance of ``[δp, ω]`` about the mean.
5. Resampling when ``N_eff < ess_threshold · N`` (systematic, or multinomial as table 6.3),
   then roughening (table 7.9): ``σ_j = 𝒢 E_j N^(−1/6)`` with E_j the range of component j of
   ``[δp, ω]`` over the cloud, jitter added in GRP about the mean attitude.

Hot loops (propagation + predicted magnitudes fused, GRP charts) are ``numba.njit(parallel)``
kernels over particles; all random numbers come from one ``numpy.random.Generator`` seeded by
``seed`` and are drawn in a fixed order, so a run is reproducible bit for bit for a given seed
(independent of the thread count). :func:`run_bpf_numpy` is the same algorithm in plain
vectorised NumPy (the benchmark's reference; also used for shapes whose BRDFs have no kernel).
"""

from __future__ import annotations

import time

import numpy as np

from .. import rotations as rot
from ..estimation.particles import multinomial_resample, roughening_sigma, systematic_resample
from . import _kernels as K
from ._common import GRP_A, GRP_F, FilterProblem, Recorder, psd_sqrt
from .result import Estimate, FLAG_COLLAPSE, FLAG_NAN, FLAG_RESAMPLED

__all__ = ["run_bpf", "run_bpf_numpy"]

_RESAMPLERS = {"systematic": systematic_resample, "multinomial": multinomial_resample}


def _check(particles, roughening, resampling, ess_threshold):
    n = int(particles)
    if n < 2:
        raise ValueError(f"particles must be >= 2, got {particles}")
    g = float(roughening)
    if not (g >= 0 and np.isfinite(g)):
        raise ValueError(f"roughening must be finite and >= 0, got {roughening}")
    if resampling not in _RESAMPLERS:
        raise ValueError(f"resampling must be one of {', '.join(_RESAMPLERS)}, got {resampling!r}")
    e = float(ess_threshold)
    if not 0.0 <= e <= 1.0:
        raise ValueError(f"ess_threshold must lie in [0, 1], got {ess_threshold}")
    return n, g, e


# --------------------------------------------------------------------------------------------
# chart helpers: numba (parallel) and numpy versions of the same maps
# --------------------------------------------------------------------------------------------

def _grp_rel_np(Q, qref):
    d = rot.quat_mult(Q, rot.quat_conj(qref)[None, :])
    d = np.where(d[:, :1] < 0, -d, d)
    return GRP_F * d[:, 1:] / (GRP_A + d[:, :1])


def _from_grp_np(P, qref):
    dq = rot.grp_to_quat(P, GRP_A, GRP_F)
    out = rot.quat_mult(dq, np.broadcast_to(qref, dq.shape))
    return out / np.linalg.norm(out, axis=1, keepdims=True)


class _NumbaOps:
    @staticmethod
    def grp_rel(Q, qref):
        return K.grp_rel_nb(Q, np.ascontiguousarray(qref), GRP_A, GRP_F)

    @staticmethod
    def from_grp(P, qref):
        return K.from_grp_rel_nb(np.ascontiguousarray(P), np.ascontiguousarray(qref), GRP_A, GRP_F)

    innov = staticmethod(K.innovation_loglik_nb)
    addnorm = staticmethod(K.add_normalize_nb)
    ess = staticmethod(K.ess_tempered_nb)

    @staticmethod
    def stats(dp, W, w):
        return K.weighted_stats_nb(np.ascontiguousarray(dp), np.ascontiguousarray(W),
                                   np.ascontiguousarray(w))


def _stats_np(dp, W, w):
    X = np.hstack([dp, W])
    mean = w @ X
    D = X - mean
    return mean, (D * w[:, None]).T @ D


def _innov_np(logw, mpred, y, sig, ll):
    fin = np.isfinite(mpred)
    r = np.where(fin, (y - np.where(fin, mpred, 0.0)) / sig, np.inf)
    ll[:] = -0.5 * r * r
    if not np.any(fin):
        return np.nan, np.nan, False
    wp = np.exp(logw[fin] - logw.max())
    wp /= wp.sum()
    mean = float(wp @ mpred[fin])
    return mean, float(wp @ (mpred[fin] - mean) ** 2), True


def _addnorm_np(logw, ll, phi, w):
    if phi != 0.0:
        logw += phi * ll
    mx = logw.max()
    if not mx > -np.inf:
        return 0.0, False
    e = np.exp(logw - mx)
    s = e.sum()
    logw -= mx + np.log(s)
    w[:] = e / s
    return float(1.0 / np.dot(w, w)), True


def _ess_np(logw, ll, phi):
    a = logw + phi * ll if phi != 0.0 else logw
    mx = a.max()
    if not mx > -np.inf:
        return 0.0
    e = np.exp(a - mx)
    return float(e.sum() ** 2 / np.dot(e, e))


class _NumpyOps:
    grp_rel = staticmethod(_grp_rel_np)
    from_grp = staticmethod(_from_grp_np)
    stats = staticmethod(_stats_np)
    innov = staticmethod(_innov_np)
    addnorm = staticmethod(_addnorm_np)
    ess = staticmethod(_ess_np)


def _mean_cov(ops, Q, W, w):
    """GRP mean and covariance of [δp, ω] (eq. 7.100–7.105).

    The chart is centred on one refinement of the heaviest particle: ``q_ref = grp2q(Σ w δp)
    ⊗ q_max``; returns ``(q̂, ω̂, C, δp about q_ref, q_ref)`` with ``q̂ = grp2q(δp̄) ⊗ q_ref``.
    """
    qmax = Q[int(np.argmax(w))].copy()
    dp = ops.grp_rel(Q, qmax)
    qref = rot.quat_mult(rot.grp_to_quat(w @ dp, GRP_A, GRP_F), qmax)
    qref = qref / np.linalg.norm(qref)
    dp = ops.grp_rel(Q, qref)
    mean, C = ops.stats(dp, W, w)
    qhat = rot.quat_mult(rot.grp_to_quat(mean[:3], GRP_A, GRP_F), qref)
    return qhat / np.linalg.norm(qhat), mean[3:].copy(), 0.5 * (C + C.T), dp, qref


# --------------------------------------------------------------------------------------------
# the filter (one loop; `backend` selects numba kernels or numpy)
# --------------------------------------------------------------------------------------------

def run_bpf(problem: FilterProblem, *, particles=10_000, seed=0, roughening=0.2,
            resampling="systematic", ess_threshold=0.5, progressive=True,
            max_stages=30, keep_clouds=(), cloud_size=2000) -> Estimate:
    """Run the bootstrap particle filter with numba kernels (module docstring) → Estimate.

    Parameters
    ----------
    problem : FilterProblem
    particles : int ≥ 2
    seed : int — seeds every random draw (reproducible bit for bit).
    roughening : float ≥ 0 — the constant 𝒢 of table 7.9 (0 disables roughening).
    resampling : {"systematic", "multinomial"}
    ess_threshold : float in [0, 1] — resample when N_eff < ess_threshold · N.
    progressive : bool — progressive correction of peaked likelihoods (step 3b); False gives
        the plain bootstrap filter of the thesis.
    max_stages : int — most tempering stages per measurement.
    keep_clouds : sequence of int — epochs (negative from the end) at which to keep the error
        rotation vectors of ``cloud_size`` particles (needs truth; for fig. 9.6-style plots).
    """
    backend = "numba" if problem.model.kernel_ok else "numpy"
    return _run(problem, particles, seed, roughening, resampling, ess_threshold, backend,
                progressive, max_stages, keep_clouds, cloud_size)


def run_bpf_numpy(problem: FilterProblem, *, particles=10_000, seed=0, roughening=0.2,
                  resampling="systematic", ess_threshold=0.5, progressive=True,
                  max_stages=30) -> Estimate:
    """The same bootstrap particle filter in plain vectorised NumPy (benchmark reference).

    Uses the same random draws in the same order as :func:`run_bpf`; results agree with it up
    to floating-point round-off (which can change a resampling decision late in a run).
    """
    return _run(problem, particles, seed, roughening, resampling, ess_threshold, "numpy",
                progressive, max_stages)


def _propagate_np(dyn, Q, W, dt):
    if dt == 0.0:
        return Q, W
    if dyn.kind == "controlled":
        Qn = rot.quat_mult(rot.rotvec_to_quat(W * dt), Q)
        return Qn / np.linalg.norm(Qn, axis=1, keepdims=True), W
    J, Ji = dyn.J, dyn.J_inv
    n = dyn.nsub(dt)
    h = dt / n

    def f(q, w):
        qd = 0.5 * rot.quat_mult(np.concatenate([np.zeros((w.shape[0], 1)), w], axis=1), q)
        wd = (-np.cross(w, w @ J.T)) @ Ji.T
        return qd, wd

    q, w = Q, W
    for _ in range(n):
        k1q, k1w = f(q, w)
        k2q, k2w = f(q + 0.5 * h * k1q, w + 0.5 * h * k1w)
        k3q, k3w = f(q + 0.5 * h * k2q, w + 0.5 * h * k2w)
        k4q, k4w = f(q + h * k3q, w + h * k3w)
        q = q + h / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q)
        w = w + h / 6.0 * (k1w + 2 * k2w + 2 * k3w + k4w)
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return q, w


def _flux_numpy(shape, sb, ob):
    """Σ_i A_i (n̂·ŝ)⁺(n̂·ô)⁺ f_r,i in plain NumPy for Lambert / Cook–Torrance facets.

    sb, ob (N,3) body-frame unit vectors. The same formulas as
    :mod:`lightcurve.photometry.kernels` (Cook–Torrance in the DESIGN.md form: Beckmann D,
    G = min(1, 2(n̂·ĥ)(n̂·ô)/(ô·ĥ), 2(n̂·ĥ)(n̂·ŝ)/(ô·ĥ)), standard Fresnel with n from F0);
    returns None when a facet uses another BRDF.
    """
    from ..photometry.kernels import COOK_TORRANCE, LAMBERT

    n, areas, ids, prm = shape.kernel_arrays()
    if not np.all((ids == LAMBERT) | (ids == COOK_TORRANCE)):
        return None
    ns = sb @ n.T                                   # (N,F)
    no = ob @ n.T
    vis = (ns > 0) & (no > 0)
    h = sb + ob
    hn = np.linalg.norm(h, axis=1, keepdims=True)
    hh = h / np.where(hn > 0, hn, 1.0)
    nh = hh @ n.T                                   # (N,F)
    c = np.sum(ob * hh, axis=1, keepdims=True)      # (N,1)
    lam = ids == LAMBERT
    xi = np.where(lam, 1.0, prm[:, 0])
    a = np.where(lam, prm[:, 0], prm[:, 1])
    mm = np.where(lam, 1.0, prm[:, 2])
    diff = xi * a / np.pi * ns * no
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        nh2 = nh * nh
        D = np.exp((nh2 - 1.0) / (nh2 * mm * mm)) / (np.pi * mm * mm * nh2 * nh2)
        G = np.minimum(1.0, np.minimum(2.0 * nh * no / c, 2.0 * nh * ns / c))
        sf = np.sqrt(np.where(lam, 0.5, a))
        nr = (1.0 + sf) / (1.0 - sf)
        g = np.sqrt(nr * nr + c * c - 1.0)
        A = (g - c) / (g + c)
        B = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        F = 0.5 * A * A * (1.0 + B * B)
        spec = (1.0 - xi) * 0.25 * F * D * G
    spec = np.where((xi < 1.0) & (nh > 0.0) & (c > 0.0) & ~lam, spec, 0.0)
    return np.sum(np.where(vis, areas * (diff + spec), 0.0), axis=1)


def _predict_np(model, Q, k):
    """Predicted magnitudes (N,) of attitudes Q (N,4) at epoch k in plain NumPy."""
    from ..photometry.magnitude import apparent_magnitude

    sb = rot.quat_rotate(Q, model.s_eci[k][None, :])
    ob = rot.quat_rotate(Q, model.o_eci[k][None, :])
    fl = _flux_numpy(model.shape, sb, ob)
    if fl is not None:
        with np.errstate(divide="ignore"):
            return np.where(fl > 0, model.offset[k] - 2.5 * np.log10(np.where(fl > 0, fl, 1.0)),
                            np.inf)
    with np.errstate(divide="ignore"):
        mm = apparent_magnitude(model.shape, Q[None, :, :], model.s_eci[k:k + 1],
                                model.o_eci[k:k + 1], model.range_obs[k:k + 1],
                                model.range_sun[k:k + 1], sun_mag=model.sun_mag)[0]
    return mm + model.lit_offset[k]


def _run(p: FilterProblem, particles, seed, roughening, resampling, ess_threshold, backend,
         progressive=True, max_stages=30, keep_clouds=(), cloud_size=2000):
    N, G, ess_thr = _check(particles, roughening, resampling, ess_threshold)
    max_stages = int(max_stages)
    keep = {int(k) % p.n for k in keep_clouds} if p.truth_q is not None else set()
    clouds = {}
    t0 = time.perf_counter()
    m = p.model
    dyn = p.dynamics
    rec = Recorder(p, "bpf")
    rec.stages = np.zeros(p.n, dtype=np.int64)
    ops = _NumbaOps if backend == "numba" else _NumpyOps
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xB9F]))
    resample = _RESAMPLERS[resampling]
    mode = 0 if dyn.kind == "controlled" else 1
    J = np.ascontiguousarray(dyn.J if dyn.J is not None else np.eye(3))
    Ji = np.ascontiguousarray(dyn.J_inv if dyn.J_inv is not None else np.eye(3))
    n_arr, a_arr, ids, prm = m._karrs
    zc = dyn.zeta_cov

    X0 = rng.standard_normal((N, 6)) @ psd_sqrt(p.P0).T
    Q = np.ascontiguousarray(ops.from_grp(X0[:, :3], p.q0))
    W = np.ascontiguousarray(p.omega0[None, :] + X0[:, 3:])
    logw = np.full(N, -np.log(N))
    w_mean = p.omega0.copy()
    empty6 = np.zeros((0, 6))
    empty3 = np.zeros((0, 3))
    nan3 = np.full(3, np.nan)
    mpred = np.empty(N)
    ll = np.zeros(N)
    w = np.full(N, 1.0 / N)
    for k in range(p.n):
        dt = float(m.t[k] - m.t[k - 1]) if k > 0 else 0.0
        z = empty6
        L = np.zeros((6, 6))
        if dt != 0.0:
            _, Qd = dyn.transition(w_mean, dt)
            if p.random_walk_zeta():
                Qd = Qd.copy()
                Qd[:3, :3] += zc
            L = np.ascontiguousarray(psd_sqrt(Qd))
            if L.shape[1]:
                z = rng.standard_normal((N, L.shape[1]))   # noise sample = z Lᵀ
        y = m.y[k]
        has_y = bool(np.isfinite(y))
        zeta = empty3
        if has_y and p.jitter_zeta():
            zeta = rng.standard_normal((N, 3)) * dyn.acs_sigma
        if backend == "numba":
            s = m.s_eci[k] if has_y else nan3
            K.bpf_predict_nb(Q, W, dt, mode, J, Ji, dyn.nsub(dt) if mode else 1, z, L, zeta,
                             s, m.o_eci[k], n_arr, a_arr, ids, prm, float(m.offset[k]), mpred)
        else:
            Q, W = _propagate_np(dyn, Q, W, dt)
            if z.shape[0]:
                noise = z @ L.T
                Q = rot.quat_mult(rot.rotvec_to_quat(noise[:, :3]), Q)
                Q = Q / np.linalg.norm(Q, axis=1, keepdims=True)
                W = W + noise[:, 3:]
            if has_y:
                Qm = Q
                if zeta.shape[0]:
                    Qm = rot.quat_mult(rot.rotvec_to_quat(zeta), Q)
                mpred = _predict_np(m, Qm, k)
        if not has_y:
            rec.flags[k] |= FLAG_NAN
            rec.skipped_nan += 1
            neff, _ = ops.addnorm(logw, ll, 0.0, w)
        else:
            sig = float(m.sigma[k])
            yhat, var_m, any_fin = ops.innov(logw, mpred, float(y), sig, ll)
            if any_fin:
                rec.innovation(k, y - yhat, var_m + sig * sig)
            if progressive:
                # progressive correction (module docstring, step 3b): temper the likelihood in
                # stages while the full update would leave N_eff below the threshold
                rest = 1.0
                for _stage in range(max_stages):
                    if ops.ess(logw, ll, rest) >= ess_thr * N:
                        break
                    phi = _temper_exponent(ops, logw, ll, rest, ess_thr * N)
                    if not phi > 0.0:
                        break
                    _, ok = ops.addnorm(logw, ll, phi, w)
                    if not ok:
                        break
                    rest -= phi
                    idx = resample(w, rng)
                    Q = np.ascontiguousarray(Q[idx])
                    W = np.ascontiguousarray(W[idx])
                    if zeta.shape[0]:
                        zeta = np.ascontiguousarray(zeta[idx])
                    logw = np.full(N, -np.log(N))
                    rec.flags[k] |= FLAG_RESAMPLED
                    _, _, _, dps, qst = _mean_cov(ops, Q, W, np.full(N, 1.0 / N))
                    Q, W = _roughen(ops, Q, W, qst, G, rng, attitude_only=True, dp=dps)
                    mpred = _predict_only(backend, m, k, Q, W, zeta, n_arr, a_arr, ids, prm, J, Ji)
                    ops.innov(logw, mpred, float(y), sig, ll)
                    rec.stages[k] += 1
            else:
                rest = 1.0
            neff, ok = ops.addnorm(logw, ll, rest, w)
            if not ok:
                rec.flags[k] |= FLAG_COLLAPSE
                logw = np.full(N, -np.log(N))
                neff, _ = ops.addnorm(logw, ll, 0.0, w)
        rec.neff[k] = neff
        qhat, what, C, dp, qref = _mean_cov(ops, Q, W, w)
        if k in keep:
            # weighted draw of cloud_size particles (separate stream: does not perturb the run)
            crng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xC10D, k]))
            sel = crng.choice(N, size=min(int(cloud_size), N), p=w)
            tq = np.broadcast_to(p.truth_q[k] / np.linalg.norm(p.truth_q[k]), (sel.size, 4))
            clouds[k] = np.degrees(rot.attitude_error_rotvec(tq, Q[sel]))
        w_mean = what
        rec.store(k, qhat, what, C)
        if has_y and neff < ess_thr * N:
            idx = resample(w, rng)
            Q = np.ascontiguousarray(Q[idx])
            W = np.ascontiguousarray(W[idx])
            logw = np.full(N, -np.log(N))
            rec.flags[k] |= FLAG_RESAMPLED
            Q, W = _roughen(ops, Q, W, qref, G, rng, dp=dp[idx])
    est = rec.finish(time.perf_counter() - t0)
    est.meta["tempering_stages"] = rec.stages.tolist()
    est.clouds = clouds or None
    return est


def _roughen(ops, Q, W, qref, G, rng, attitude_only=False, dp=None):
    """Roughening (table 7.9): jitter σ_j = 𝒢 E_j N^(−1/d) on [δp (GRP about qref), ω] (d = 6).

    ``attitude_only``: jitter only δp (d = 3) — used between tempering stages of one
    measurement, which constrains the attitude but not the rate (jittering ω there would
    inflate its spread stage after stage). ``dp``: the GRP of Q about qref if already known.
    """
    if not G > 0.0:
        return Q, W
    if dp is None:
        dp = ops.grp_rel(Q, qref)
    if attitude_only:
        sg = roughening_sigma(dp, G, d=3)
        dp = dp + rng.standard_normal(dp.shape) * sg[None, :]
        return np.ascontiguousarray(ops.from_grp(dp, qref)), W
    X = np.hstack([dp, W])
    sg = roughening_sigma(X, G, d=6)
    X = X + rng.standard_normal(X.shape) * sg[None, :]
    return np.ascontiguousarray(ops.from_grp(X[:, :3], qref)), np.ascontiguousarray(X[:, 3:])


def _temper_exponent(ops, logw, ll, rest, target):
    """Largest φ ∈ (0, rest] with N_eff(logw + φ ll) ≥ target (bisection, 24 steps)."""
    lo, hi = 0.0, rest
    for _ in range(24):
        mid = 0.5 * (lo + hi)
        if ops.ess(logw, ll, mid) >= target:
            lo = mid
        else:
            hi = mid
    return lo


def _predict_only(backend, m, k, Q, W, zeta, n_arr, a_arr, ids, prm, J, Ji):
    """Predicted magnitudes (N,) of the particles at epoch k without moving them."""
    out = np.empty(Q.shape[0])
    if backend == "numba":
        K.bpf_predict_nb(Q, W, 0.0, 0, J, Ji, 1, np.zeros((0, 6)), np.zeros((6, 6)), zeta,
                         m.s_eci[k], m.o_eci[k], n_arr, a_arr, ids, prm, float(m.offset[k]), out)
        return out
    Qm = Q
    if zeta.shape[0]:
        Qm = rot.quat_mult(rot.rotvec_to_quat(zeta), Q)
    return _predict_np(m, Qm, k)
