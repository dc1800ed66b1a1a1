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
   with log-sum-exp; ``N_eff = 1/Σ w_i²``. Before that (:mod:`lightcurve.filters.gating`):
   epochs with the object unlit or below the horizon are skipped, and a magnitude far outside
   the particles' predictive spread (``ν²/S`` with ``ν = y − Σ w m(q_i)``,
   ``S = Σ w (m(q_i) − ŷ)² + σ²``, above the χ² gate) leaves the weights unchanged (or is used
   with an inflated σ), flagged and counted.
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

Extra states (Bernard ch. 8; issue 6)
-------------------------------------
* Site biases (``bias=``, :class:`~lightcurve.filters.reflection.SiteBias`: random walk,
  Model 1, Model 2): every particle carries ``b_s`` per site, drawn from ``N(0, var0)``,
  propagated with the model's exact discrete transition ``b ← φ_b b + √q_b · N(0,1)`` (φ_b,
  q_b from ``SiteBias.transition(Δt, ω̂)`` at the mean rate), and the likelihood uses
  ``m(q_i) + b_i,site``. The Estimate carries ``bias`` / ``bias_sigma`` (weighted mean and
  standard deviation, mag) like the Kalman filters.
* Model 3 (``facets=``, :class:`~lightcurve.filters.facet_states.FacetParameterStates`):
  every particle carries the D unbounded facet parameters z (logit ξ, logit a, ln m, ln A;
  24 for a 6-facet cube) drawn from the shape file's prior, constant dynamics (eq. 8.39; the
  optional process noise of ``FacetParameterStates``), and the magnitude is evaluated with
  per-particle facet arrays by :func:`~lightcurve.filters._kernels.facet_mag_particles_nb`
  (the attitude-only kernel path is unchanged). The Estimate carries ``refl_p`` /
  ``refl_p_sigma`` (weighted mean / standard deviation of p(z)) and ``refl_z`` /
  ``refl_z_sigma`` per epoch.
* ``attitude="truth"``: q and ω are held at the file's truth at every epoch (Bernard §10.7
  parameter-only runs) and only the extra states are filtered.
* Roughening of the extra states: after every resampling they are jittered with the
  Liu & West (2001) kernel shrinkage ``e ← a e + (1−a) ē + h L ε`` (``a = (3δ−1)/(2δ)``,
  ``h² = 1 − a²``, L L^T the cloud's covariance, δ = ``param_discount``, 0.98 by default).
  This is our choice, not the thesis's table 7.9: table 7.9's jitter ``𝒢 E_j N^(−1/d)`` with
  d = 30 states is about one cloud standard deviation per resampling and would inflate a
  constant parameter's spread at every step; the shrinkage keeps the cloud's mean and
  covariance, with a jitter scaled by the cloud's own spread. The attitude/rate roughening is
  unchanged (table 7.9).
* Resample-move (attitude known, Model 3; ``mcmc_moves``): after every resampling each
  particle's z takes Metropolis random-walk steps (Gilks & Berzuini 2001) whose target is the
  exact posterior given the known attitude history, ``π(z) Π_{j<k} L_j(z) L_k(z)^φ`` (φ the
  tempering exponent reached), proposal scale ``2.38/√D`` times the cloud's covariance
  square root; this replaces the Liu–West jitter there. It costs a pass over the past
  measurements per move (O(k N)) and is possible only because the attitude is known. With
  the attitude estimated the past likelihood depends on each particle's attitude path, which
  the filter does not keep, so the combined runs use the joint kernel below.
* Rejuvenation of the combined state (``rejuvenation=``; default "auto" = "joint" whenever the
  attitude is estimated, "separate" when it is held at the truth): after every resampling — at the end of
  an epoch and between progressive-correction stages — the full state ``x = [δp, ω, z]``
  (GRP about the mean attitude, rate, the 24 facet parameters: d = 30) is moved with one
  Liu & West (2001) shrinkage kernel ``x ← a x + (1−a) x̄ + h L ε``, ``L Lᵀ`` the cloud's
  full covariance, ``a = √(1 − h²)``, and ``h`` the optimal Gaussian-kernel bandwidth of the
  regularised particle filter, ``h = (4/(d+2))^(1/(d+4)) N^(−1/(d+4))`` (Musso, Oudjane &
  Le Gland 2001; ≈ 0.72 for d = 30, N = 10⁴), or ``kernel_bandwidth``. Mean and covariance
  (with the attitude–parameter cross-covariances) are kept in expectation. Why (measured
  with benchmarks/reflection_bpf.py --combined, session 3): with the "separate" scheme the
  rate is roughened only by the end-of-epoch resampling, which progressive correction makes
  rare (it leaves N_eff ≥ the threshold), while the tempering stages resample and jitter
  the attitude only — so the controlled filter's rate cloud (no process noise) degenerates
  to a single value within ≈ 12 epochs, the attitude then drifts with the frozen rate error
  and the small Liu–West jitter (δ = 0.98, h = 0.14) cannot keep 24 parameters spread in
  30 dimensions: the cloud collapsed. LEO fast spin, seeds 2000–2009, 10⁴ particles,
  σθ = 3°/10°: final attitude inside 3σ 0/10 → 10/10 (both), parameters inside 3σ
  20 %/11 % → 99 %/98 %, median final error 1.27°/2.11° → 0.85°/0.86°; the joint kernel
  with the old small bandwidth (h = 0.14) still fails (0/10), h = 0.33–0.5 works (9–10/10).
  The wide joint kernel is our choice (not the thesis's table 7.9, which roughens [δp, ω]
  only, with the range E_j; with "joint" the ``roughening`` constant is not used).
  "separate" keeps the previous scheme bit for bit. The attitude-only filter showed the same
  rate collapse, so "joint" is its default too since session 3 — but only while the resampled
  attitude cloud is compact (largest per-axis σ of its GRP error < ``joint_max_spread_deg``,
  default 25°); a wider cloud gets the separate roughening. Applied at every resampling, the
  kernel's shrinkage toward the mean merged the modes of wide multimodal clouds: σθ = 60°
  attitude-only runs (the thesis LEO fast-spin case, seeds 0–19) then ended ≈ 170° off in 19 of 20.
  Measured, 10⁴ particles, 20 seeds per row; final attitude inside 3σ (diverged) and median
  final RSS error for separate → auto with the threshold at 10° / 25° (default):
  LEO fast spin controlled 1 site (seeds 3000–3019) σθ 3°: 10/20 → 19/20 / 19/20, 0.67° →
  0.73°; σθ 10°: 4/20 → 20/20 / 20/20, 0.79° → 0.73° / 0.80°; uncontrolled 2 sites σθ 3°:
  0/20 (4) → 19/20 (1), 1.00° → 0.20°; σθ 10°: 0/20 (6) → 17/20 (3) / 13/20 (5), 0.95° →
  0.27° / 0.26°; default scenario σθ = 60° (seeds 0–19): below 5° 20/20 → 20/20 / 20/20,
  inside 9/20 → 16/20 / 17/20, 0.86° → 0.67° / 0.64°. Model 3 combined σθ 10° (seeds
  2000–2009): 10° threshold 8/10 inside, attitude+rate NEES sum 205 (χ²₆₀ 99.9 % bound 99.6),
  parameters inside 3σ 94.6 %; 25° threshold 10/10, NEES 81.9, 97.9 % — hence 25°.
* Random draws: the extra-state initial draw follows the attitude draw, the extra-state noise
  follows the attitude noise at each step, the jitter follows the attitude roughening, so the
  attitude-only filter is unchanged bit for bit and every run is deterministic per seed.

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
from ..errors import InputError
from ..estimation.particles import multinomial_resample, roughening_sigma, systematic_resample
from . import _kernels as K
from ._common import GRP_A, GRP_F, FilterProblem, Recorder, attach_bias, psd_sqrt
from .gating import InnovationGate
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
            max_stages=30, keep_clouds=(), cloud_size=2000, bias=None, facets=None,
            attitude="estimate", param_discount=0.98, mcmc_moves=None,
            rejuvenation="auto", kernel_bandwidth=None,
            joint_max_spread_deg=25.0) -> Estimate:
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
    bias : :class:`lightcurve.filters.reflection.SiteBias` or None — per-site magnitude-bias
        states (random walk, Model 1, Model 2); the Estimate then carries ``bias`` and
        ``bias_sigma`` (N,S), mag.
    facets : :class:`lightcurve.filters.facet_states.FacetParameterStates` or None — Model 3
        facet-parameter states; the Estimate then carries ``refl_names`` and per epoch
        ``refl_p`` / ``refl_p_sigma`` (physical; weighted particle mean and standard
        deviation of p(z)) and ``refl_z`` / ``refl_z_sigma`` (unbounded), each (N,D).
    attitude : {"estimate", "truth"} — "truth" (or ``problem.attitude_known``) holds q and ω
        at the lightcurve's truth (§10.7 parameter-only runs; needs truth in the file) and
        estimates only the extra states.
    param_discount : float in (0, 1] — Liu–West discount δ of the extra states' roughening
        (1 disables it); module docstring, "Extra states". Used by the "separate"
        rejuvenation only (the joint kernel takes ``kernel_bandwidth``).
    mcmc_moves : int ≥ 0 or None — attitude-known Model 3 runs only: Metropolis resample-move
        steps per resampling instead of the Liu–West jitter (module docstring; 0: off, the
        plain bootstrap filter). None (default): 1 for attitude-known Model 3 runs, where the
        plain filter's posterior collapses (benchmarks/reflection_bpf.py --acceptance), else 0.
    rejuvenation : {"auto", "separate", "joint"} — how the cloud is moved after resampling
        (module docstring, "Rejuvenation of the combined state"): "separate" = table 7.9 on
        [δp, ω] (attitude only between tempering stages) plus the Liu–West jitter (or
        resample-move) of the extra states; "joint" = one Liu–West kernel on the full state
        (attitude estimated only; ``roughening`` unused while it applies); "auto" = "joint"
        when the attitude is estimated, "separate" when it is held at the truth.
    kernel_bandwidth : float in [0, 1) or None — h of the joint kernel; None = the Musso et
        al. (2001) optimum for d = 6 + extra states and N particles (0 disables the kernel).
    joint_max_spread_deg : float > 0 — the joint kernel is applied only while the resampled
        attitude cloud is compact: largest per-axis standard deviation of its GRP error below
        this (deg, default 25; module docstring for the measurements); a wider cloud gets the "separate" roughening (a wide cloud
        is often multimodal, and the kernel's shrinkage toward the mean would merge the
        modes: with the joint kernel at every resampling, σθ = 60° attitude-only runs ended
        ≈ 170° off in 19 of 20 seeds). ``meta["rejuvenation"]["joint_applied"]`` counts the
        resamplings that used the kernel.
    """
    backend = "numba" if problem.model.kernel_ok else "numpy"
    return _run(problem, particles, seed, roughening, resampling, ess_threshold, backend,
                progressive, max_stages, keep_clouds, cloud_size, bias=bias, facets=facets,
                attitude=attitude, param_discount=param_discount, mcmc_moves=mcmc_moves,
                rejuvenation=rejuvenation, kernel_bandwidth=kernel_bandwidth,
                joint_max_spread_deg=joint_max_spread_deg)


def run_bpf_numpy(problem: FilterProblem, *, particles=10_000, seed=0, roughening=0.2,
                  resampling="systematic", ess_threshold=0.5, progressive=True,
                  max_stages=30, bias=None, facets=None, attitude="estimate",
                  param_discount=0.98, mcmc_moves=None, rejuvenation="auto",
                  kernel_bandwidth=None, joint_max_spread_deg=25.0) -> Estimate:
    """The same bootstrap particle filter in plain vectorised NumPy (benchmark reference).

    Uses the same random draws in the same order as :func:`run_bpf`; results agree with it up
    to floating-point round-off (which can change a resampling decision late in a run).
    """
    return _run(problem, particles, seed, roughening, resampling, ess_threshold, "numpy",
                progressive, max_stages, bias=bias, facets=facets, attitude=attitude,
                param_discount=param_discount, mcmc_moves=mcmc_moves,
                rejuvenation=rejuvenation, kernel_bandwidth=kernel_bandwidth,
                joint_max_spread_deg=joint_max_spread_deg)


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


def _flux_numpy(shape, sb, ob, areas=None, prm=None):
    """Σ_i A_i (n̂·ŝ)⁺(n̂·ô)⁺ f_r,i in plain NumPy for Lambert / Cook–Torrance facets.

    sb, ob (N,3) body-frame unit vectors; ``areas`` (N,F) m² and ``prm`` (N,F,P) per-particle
    kernel arrays (Model 3) replace the shape's when given. The same formulas as
    `lightcurve.core.photometry` (Cook–Torrance in the DESIGN.md form: Beckmann D,
    G = min(1, 2(n̂·ĥ)(n̂·ô)/(ô·ĥ), 2(n̂·ĥ)(n̂·ŝ)/(ô·ĥ)), standard Fresnel with n from F0);
    returns None when a facet uses another BRDF.
    """
    from ..core.photometry import COOK_TORRANCE, LAMBERT

    n, areas0, ids, prm0 = shape.kernel_arrays()
    areas = areas0 if areas is None else areas
    prm = prm0 if prm is None else prm
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
    xi = np.where(lam, 1.0, prm[..., 0])
    a = np.where(lam, prm[..., 0], prm[..., 1])
    mm = np.where(lam, 1.0, prm[..., 2])
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
    spec = np.where((nh > 0.0) & (c > 0.0) & ~lam, spec, 0.0)
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


class _Extra:
    """Per-particle extra states appended to ``(q, ω)`` (module docstring, "Extra states").

    ``kind`` None (attitude only), ``"bias"`` (site biases ``b_s``, mag, (N,S)) or ``"facets"``
    (Model 3 unbounded facet parameters z, (N,D)). ``E`` holds the cloud.
    """

    def __init__(self, p, bias, facets, N, rng, discount):
        self.bias, self.facets = bias, facets
        self.kind = None if bias is None and facets is None else ("bias" if bias is not None
                                                                   else "facets")
        d = float(discount)
        if not (0.0 < d <= 1.0):
            raise ValueError(f"param_discount must lie in (0, 1], got {discount}")
        # Liu & West (2001) kernel shrinkage: a = (3δ − 1)/(2δ), h² = 1 − a²
        self.a = (3.0 * d - 1.0) / (2.0 * d)
        self.h = float(np.sqrt(max(0.0, 1.0 - self.a * self.a)))
        self.site = np.asarray(p.model.site, np.int64)
        if self.kind == "bias":
            self.ne = bias.n_sites
            self.E = rng.standard_normal((N, self.ne)) * np.sqrt(bias.var0)[None, :]
        elif self.kind == "facets":
            self.ne = facets.dim
            L0 = np.linalg.cholesky(facets.P0)
            self.E = facets.z0[None, :] + rng.standard_normal((N, self.ne)) @ L0.T
            self.kc = np.ascontiguousarray(facets.kind_col, dtype=np.int64)
            self.fc = np.ascontiguousarray(facets.facet, dtype=np.int64)
            self.lg = np.ascontiguousarray(facets.logit, dtype=np.bool_)
            self.areas0 = np.ascontiguousarray(facets._areas0)
            self.params0 = np.ascontiguousarray(facets._params0)
        else:
            self.ne = 0
            self.E = np.zeros((N, 0))
        self.E = np.ascontiguousarray(self.E)
        n = p.n
        self.mean = np.full((n, self.ne), np.nan)
        self.sd = np.full((n, self.ne), np.nan)
        if self.kind == "facets":
            self.pmean = np.full((n, self.ne), np.nan)
            self.psd = np.full((n, self.ne), np.nan)

    def propagate(self, dt, w_mean, rng):
        """Exact discrete transition over dt s: ``b ← φ_b b + √q_b · N(0,1)`` (site biases,
        :meth:`SiteBias.transition` at the mean rate) or ``z ← z + √(q_z Δt) · N(0,1)``
        (Model 3, eq. 8.39; no draw when the process noise is 0)."""
        if dt == 0.0 or self.kind is None:
            return
        if self.kind == "bias":
            phi, qb = self.bias.transition(dt, w_mean)
            if np.any(phi != 1.0):
                self.E *= phi[None, :]
            if np.any(qb > 0.0):
                self.E += rng.standard_normal(self.E.shape) * np.sqrt(qb)[None, :]
        else:
            qz = self.facets.process_noise * abs(dt)
            if qz > 0.0:
                self.E += rng.standard_normal(self.E.shape) * np.sqrt(qz)

    def add_bias(self, mpred, k):
        """``m_i ← m_i + b_i,site(k)`` in place (site-bias model only)."""
        if self.kind == "bias":
            mpred += self.E[:, self.site[k]]

    def take(self, idx):
        if self.ne:
            self.E = np.ascontiguousarray(self.E[idx])

    def jitter(self, rng):
        """Liu–West shrinkage roughening of the (resampled, equally weighted) extra states:
        ``e_i ← a e_i + (1 − a) ē + h L ε_i`` with ``L Lᵀ`` the cloud covariance and
        ``ε_i ~ N(0, I)`` — mean and covariance of the cloud are kept (in expectation), so a
        constant parameter is not inflated at every resampling, while duplicated particles
        are separated. The jitter scale is set by the cloud's own spread."""
        if not self.ne or self.h == 0.0:
            return
        mean, V = K.mean_cov_nb(self.E)
        L = psd_sqrt(V)
        if not L.shape[1]:
            return
        eps = rng.standard_normal((self.E.shape[0], L.shape[1]))
        out = np.empty_like(self.E)
        K.affine_rows_nb(eps, np.ascontiguousarray(self.h * L), self.a, (1.0 - self.a) * mean,
                         self.E, out)
        self.E = out

    def setup_moves(self, p, n_moves, tq):
        """Resample-move (attitude known, Model 3): ``n_moves`` Metropolis steps per
        resampling, targeting the exact posterior of z given the known attitude history."""
        self.n_moves = int(n_moves)
        if self.n_moves < 0:
            raise ValueError(f"mcmc_moves must be >= 0, got {n_moves}")
        self.n_prop = 0
        self.n_acc = 0
        if not self.n_moves:
            return
        if self.kind != "facets" or tq is None:
            raise ValueError("mcmc_moves needs Model 3 facet states and attitude='truth'")
        m = p.model
        self._hist = (np.ascontiguousarray(tq), m.s_eci, m.o_eci,
                      np.ascontiguousarray(m.offset, dtype=float),
                      np.ascontiguousarray(m.y, dtype=float),
                      np.ascontiguousarray(m.sigma, dtype=float), m._karrs[0], m._karrs[2])
        self._Linv = np.linalg.inv(np.linalg.cholesky(self.facets.P0))

    def _log_post(self, Z, k, phi):
        Qs, S, O, offs, y, sig, n_arr, ids = self._hist
        ll = np.empty(Z.shape[0])
        K.facet_loglik_history_nb(Z, k, phi, Qs, S, O, offs, y, sig, self.fc, self.kc,
                                  self.lg, n_arr, self.areas0, ids, self.params0, ll)
        r = np.empty_like(Z)
        K.affine_rows_nb(Z, self._Linv, 0.0, -(self._Linv @ self.facets.z0), Z, r)
        return ll - 0.5 * np.sum(r * r, axis=1)

    def move(self, k, phi, rng):
        """Metropolis random-walk moves of every particle's z (Gilks & Berzuini 2001
        resample-move) targeting ``π(z) Π_{j<k} L_j(z) L_k(z)^φ`` (the tempered posterior at
        this stage; π the Gaussian prior in z): proposal ``z' = z + (2.38/√D) L ε`` with
        ``L Lᵀ`` the cloud covariance, acceptance ``min(1, post(z')/post(z))``. Leaves the
        target invariant, so it only rejuvenates the cloud (no artificial spread)."""
        if not self.n_moves:
            return
        D = self.ne
        L = psd_sqrt(K.mean_cov_nb(self.E)[1])
        if not L.shape[1]:
            return
        cL = np.ascontiguousarray(2.38 / np.sqrt(D) * L)
        zero = np.zeros(D)
        lp0 = self._log_post(self.E, k, phi)
        for _ in range(self.n_moves):
            Zp = np.empty_like(self.E)
            K.affine_rows_nb(rng.standard_normal((self.E.shape[0], L.shape[1])), cL, 1.0, zero,
                             self.E, Zp)
            lp1 = self._log_post(Zp, k, phi)
            u = rng.random(self.E.shape[0])
            with np.errstate(invalid="ignore"):
                acc = np.log(u) < lp1 - lp0
            acc &= np.isfinite(lp1)
            self.E[acc] = Zp[acc]
            lp0[acc] = lp1[acc]
            self.n_prop += acc.size
            self.n_acc += int(acc.sum())

    def record(self, k, w):
        """Weighted mean and 1σ of the extra states at epoch k (and of p(z) for Model 3)."""
        if not self.ne:
            return
        if self.kind == "facets":
            zm, zv, pm, pv = K.weighted_param_stats_nb(self.E, np.ascontiguousarray(w), self.lg)
            self.mean[k], self.sd[k] = zm, np.sqrt(zv)
            self.pmean[k], self.psd[k] = pm, np.sqrt(pv)
        else:
            m = w @ self.E
            self.mean[k] = m
            self.sd[k] = np.sqrt(np.clip(w @ (self.E - m) ** 2, 0.0, None))

    def attach(self, est):
        if self.kind == "bias":
            attach_bias(est, self.bias, self.mean, self.sd)
            est.meta["reflection"]["roughening"] = "liu-west"
            est.meta["reflection"]["liu_west_a"] = self.a
        elif self.kind == "facets":
            fs = self.facets
            est.refl_names = list(fs.names)
            est.refl_z, est.refl_z_sigma = self.mean, self.sd
            est.refl_p, est.refl_p_sigma = self.pmean, self.psd
            est.meta["reflection_names"] = list(fs.names)
            est.meta["reflection"] = dict(fs.describe(), p_final=self.pmean[-1].tolist(),
                                          p_sigma_final=self.psd[-1].tolist(),
                                          z_final=self.mean[-1].tolist(),
                                          z_sigma_final=self.sd[-1].tolist(),
                                          roughening=("resample-move" if self.n_moves
                                                      else "liu-west"),
                                          liu_west_a=self.a, mcmc_moves=self.n_moves,
                                          mcmc_acceptance=(self.n_acc / self.n_prop
                                                           if self.n_prop else None))


def _predict_facets(backend, p, ext, k, Q, zeta, out):
    """Predicted magnitudes (N,) with per-particle facet parameters (Model 3) at epoch k;
    Q (N,4) or (1,4) (attitude known)."""
    m = p.model
    if backend == "numba":
        n_arr, _, ids, _ = m._karrs
        K.facet_mag_particles_nb(Q, zeta, ext.E, ext.fc, ext.kc, ext.lg, m.s_eci[k], m.o_eci[k],
                                 n_arr, ext.areas0, ids, ext.params0, float(m.offset[k]), out)
        return out
    N = ext.E.shape[0]
    Qm = np.broadcast_to(Q, (N, 4)) if Q.shape[0] == 1 else Q
    if zeta.shape[0]:
        Qm = rot.quat_mult(rot.rotvec_to_quat(zeta), Qm)
    areas, prm = ext.facets.facet_arrays(ext.E)
    sb = rot.quat_rotate(Qm, m.s_eci[k][None, :])
    ob = rot.quat_rotate(Qm, m.o_eci[k][None, :])
    fl = _flux_numpy(m.shape, sb, ob, areas=areas, prm=prm)
    if fl is None:                       # BRDFs without a NumPy formula: per-particle shapes
        out[:] = ext.facets.magnitudes(m, np.ascontiguousarray(Qm), ext.E, k)
        return out
    with np.errstate(divide="ignore"):
        out[:] = np.where(fl > 0, m.offset[k] - 2.5 * np.log10(np.where(fl > 0, fl, 1.0)), np.inf)
    return out


def _run(p: FilterProblem, particles, seed, roughening, resampling, ess_threshold, backend,
         progressive=True, max_stages=30, keep_clouds=(), cloud_size=2000, bias=None,
         facets=None, attitude="estimate", param_discount=0.98, mcmc_moves=None,
         rejuvenation="auto", kernel_bandwidth=None, joint_max_spread_deg=25.0):
    N, G, ess_thr = _check(particles, roughening, resampling, ess_threshold)
    if bias is not None and facets is not None:
        raise ValueError("site biases and Model 3 facet states are alternatives; give one")
    if attitude not in ("estimate", "truth"):
        raise ValueError(f"attitude must be 'estimate' or 'truth', got {attitude!r}")
    fixed = attitude == "truth" or bool(getattr(p, "attitude_known", False))
    if fixed and (p.truth_q is None or p.truth_omega is None):
        raise InputError("attitude='truth' needs the truth attitude and rate in the lightcurve",
                         field="attitude", value=attitude)
    max_stages = int(max_stages)
    keep = {int(k) % p.n for k in keep_clouds} if (p.truth_q is not None and not fixed) else set()
    clouds = {}
    t0 = time.perf_counter()
    m = p.model
    dyn = p.dynamics
    rec = Recorder(p, "bpf")
    gate = InnovationGate(p, auto="inflate")   # outlier gate + unlit/below-horizon screening
    rec.stages = np.zeros(p.n, dtype=np.int64)
    ops = _NumbaOps if backend == "numba" else _NumpyOps
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xB9F]))
    resample = _RESAMPLERS[resampling]
    mode = 0 if dyn.kind == "controlled" else 1
    J = np.ascontiguousarray(dyn.J if dyn.J is not None else np.eye(3))
    Ji = np.ascontiguousarray(dyn.J_inv if dyn.J_inv is not None else np.eye(3))
    n_arr, a_arr, ids, prm = m._karrs
    zc = dyn.zeta_cov

    if fixed:
        tq = p.truth_q / np.linalg.norm(p.truth_q, axis=1, keepdims=True)
        Q = np.ascontiguousarray(tq[:1])
        W = np.ascontiguousarray(p.truth_omega[:1])
    else:
        X0 = rng.standard_normal((N, 6)) @ psd_sqrt(p.P0).T
        Q = np.ascontiguousarray(ops.from_grp(X0[:, :3], p.q0))
        W = np.ascontiguousarray(p.omega0[None, :] + X0[:, 3:])
    ext = _Extra(p, bias, facets, N, rng, param_discount)
    if mcmc_moves is None:
        mcmc_moves = 1 if (fixed and facets is not None) else 0
    ext.setup_moves(p, mcmc_moves, tq if fixed else None)
    joint = _resolve_rejuvenation(rejuvenation, ext, fixed)
    kern = _joint_bandwidth(kernel_bandwidth, N, 6 + ext.ne) if joint else None
    joint_spread = float(np.radians(joint_max_spread_deg))
    if not joint_spread > 0.0:
        raise ValueError(f"joint_max_spread_deg must be > 0, got {joint_max_spread_deg}")
    n_joint = 0
    logw = np.full(N, -np.log(N))
    w_mean = p.omega0.copy() if not fixed else p.truth_omega[0].copy()
    empty6 = np.zeros((0, 6))
    empty3 = np.zeros((0, 3))
    nan3 = np.full(3, np.nan)
    mpred = np.empty(N)
    ll = np.zeros(N)
    w = np.full(N, 1.0 / N)
    zero6 = np.zeros((6, 6))
    for k in range(p.n):
        dt = float(m.t[k] - m.t[k - 1]) if k > 0 else 0.0
        z = empty6
        L = np.zeros((6, 6))
        if dt != 0.0 and not fixed:
            _, Qd = dyn.transition(w_mean, dt)
            if p.random_walk_zeta():
                Qd = Qd.copy()
                Qd[:3, :3] += zc
            L = np.ascontiguousarray(psd_sqrt(Qd))
            if L.shape[1]:
                z = rng.standard_normal((N, L.shape[1]))   # noise sample = z Lᵀ
        y = m.y[k]
        has_y = bool(np.isfinite(y))
        skipped = has_y and gate.skip_epoch(k, rec)   # object unlit / below the horizon
        has_y = has_y and not skipped
        zeta = empty3
        if has_y and p.jitter_zeta() and not fixed:
            zeta = rng.standard_normal((N, 3)) * dyn.acs_sigma
        ext.propagate(dt, w_mean, rng)
        if fixed:
            Q = np.ascontiguousarray(tq[k:k + 1])
            W = np.ascontiguousarray(p.truth_omega[k:k + 1])
            if has_y:
                mpred = _predict_any(backend, p, ext, k, Q, W, zeta, J, Ji, mpred)
        elif backend == "numba":
            s = m.s_eci[k] if (has_y and ext.kind != "facets") else nan3
            K.bpf_predict_nb(Q, W, dt, mode, J, Ji, dyn.nsub(dt) if mode else 1, z, L, zeta,
                             s, m.o_eci[k], n_arr, a_arr, ids, prm, float(m.offset[k]), mpred)
            if has_y and ext.kind == "facets":
                _predict_facets(backend, p, ext, k, Q, zeta, mpred)
            elif has_y:
                ext.add_bias(mpred, k)
        else:
            Q, W = _propagate_np(dyn, Q, W, dt)
            if z.shape[0]:
                noise = z @ L.T
                Q = rot.quat_mult(rot.rotvec_to_quat(noise[:, :3]), Q)
                Q = Q / np.linalg.norm(Q, axis=1, keepdims=True)
                W = W + noise[:, 3:]
            if has_y:
                mpred = _predict_any(backend, p, ext, k, Q, W, zeta, J, Ji, mpred)
        if skipped:
            neff, _ = ops.addnorm(logw, ll, 0.0, w)
        elif not has_y:
            rec.flags[k] |= FLAG_NAN
            rec.skipped_nan += 1
            neff, _ = ops.addnorm(logw, ll, 0.0, w)
        else:
            sig = float(m.sigma[k])
            yhat, var_m, any_fin = ops.innov(logw, mpred, float(y), sig, ll)
            # innovation gate: S = particle variance of the predictions + R (gating.py)
            # (and no particle explains y: its own |y − m(q_i)| > √(γ R); gating docstring)
            R = (gate.check(k, y - yhat, var_m + sig * sig, sig * sig, rec,
                            nu_nearest=np.min(np.abs(y - mpred[np.isfinite(mpred)])))
                 if any_fin else sig * sig)
            if R is None:
                ll[:] = 0.0   # outlier rejected: the weights are left unchanged
            elif R != sig * sig:
                sig = float(np.sqrt(R))   # gate mode "inflate": the inflated noise
                ops.innov(logw, mpred, float(y), sig, ll)
            if any_fin and R is not None:
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
                    if not fixed:
                        Q = np.ascontiguousarray(Q[idx])
                        W = np.ascontiguousarray(W[idx])
                    ext.take(idx)
                    if zeta.shape[0]:
                        zeta = np.ascontiguousarray(zeta[idx])
                    logw = np.full(N, -np.log(N))
                    rec.flags[k] |= FLAG_RESAMPLED
                    if not fixed:
                        _, _, _, dps, qst = _mean_cov(ops, Q, W, np.full(N, 1.0 / N))
                    if joint and _joint_applies(dps, joint_spread):
                        Q, W = _joint_kernel(ops, Q, W, ext, qst, dps, rng, kern)
                        n_joint += 1
                    else:
                        if not fixed:
                            Q, W = _roughen(ops, Q, W, qst, G, rng, attitude_only=True, dp=dps)
                        if ext.n_moves:
                            ext.move(k, 1.0 - rest, rng)
                        else:
                            ext.jitter(rng)
                    mpred = _predict_any(backend, p, ext, k, Q, W, zeta, J, Ji, mpred)
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
        if fixed:
            qhat, what, C = tq[k], p.truth_omega[k].copy(), zero6
        else:
            qhat, what, C, dp, qref = _mean_cov(ops, Q, W, w)
        ext.record(k, w)
        if k in keep:
            # weighted draw of cloud_size particles (separate stream: does not perturb the run)
            crng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xC10D, k]))
            sel = crng.choice(N, size=min(int(cloud_size), N), p=w)
            tqk = np.broadcast_to(p.truth_q[k] / np.linalg.norm(p.truth_q[k]), (sel.size, 4))
            clouds[k] = np.degrees(rot.attitude_error_rotvec(tqk, Q[sel]))
        w_mean = what
        rec.store(k, qhat, what, C)
        if has_y and neff < ess_thr * N:
            idx = resample(w, rng)
            logw = np.full(N, -np.log(N))
            rec.flags[k] |= FLAG_RESAMPLED
            ext.take(idx)
            if joint and _joint_applies(dp[idx], joint_spread):
                Q = np.ascontiguousarray(Q[idx])
                W = np.ascontiguousarray(W[idx])
                Q, W = _joint_kernel(ops, Q, W, ext, qref, dp[idx], rng, kern)
                n_joint += 1
            else:
                if not fixed:
                    Q = np.ascontiguousarray(Q[idx])
                    W = np.ascontiguousarray(W[idx])
                    Q, W = _roughen(ops, Q, W, qref, G, rng, dp=dp[idx])
                if ext.n_moves:
                    ext.move(k, 1.0, rng)
                else:
                    ext.jitter(rng)
    est = gate.finish(rec.finish(time.perf_counter() - t0))
    est.meta["tempering_stages"] = rec.stages.tolist()
    if fixed:
        est.meta["attitude"] = "truth"
    ext.attach(est)
    if joint:
        est.meta["rejuvenation"] = {"kind": "joint", "bandwidth_h": kern[1],
                                    "shrinkage_a": kern[0], "dimension": 6 + ext.ne,
                                    "max_spread_deg": float(joint_max_spread_deg),
                                    "joint_applied": n_joint}
        if ext.kind is not None:
            est.meta["reflection"]["roughening"] = "joint-liu-west"
    est.clouds = clouds or None
    return est


def _predict_any(backend, p, ext, k, Q, W, zeta, J, Ji, out):
    """Predicted magnitudes (N,) of the current cloud at epoch k without moving it (attitude
    only, + site bias, or with per-particle facet parameters)."""
    if ext.kind == "facets":
        return _predict_facets(backend, p, ext, k, Q, zeta, out)
    m = p.model
    if Q.shape[0] != out.shape[0]:       # attitude known, no per-particle state changes m(q)
        Q = np.ascontiguousarray(np.broadcast_to(Q, (out.shape[0], 4)))
        W = np.ascontiguousarray(np.broadcast_to(W, (out.shape[0], 3)))
    n_arr, a_arr, ids, prm = m._karrs
    mp = _predict_only(backend, m, k, Q, W, zeta, n_arr, a_arr, ids, prm, J, Ji)
    out[:] = mp
    ext.add_bias(out, k)
    return out


def _resolve_rejuvenation(rejuvenation, ext, fixed):
    """True for the joint Liu–West kernel on the full state (module docstring, "Rejuvenation
    of the combined state"), False for the separate table-7.9 / extra-state roughening."""
    if rejuvenation not in ("auto", "separate", "joint"):
        raise ValueError("rejuvenation must be 'auto', 'separate' or 'joint', "
                         f"got {rejuvenation!r}")
    if rejuvenation == "auto":
        return not fixed
    if rejuvenation == "joint" and fixed:
        raise ValueError("rejuvenation='joint' needs the attitude estimated (attitude='truth' "
                         "holds q and ω at the truth; use 'separate' or mcmc_moves there)")
    return rejuvenation == "joint"


def _joint_bandwidth(h, N, d):
    """``(a, h)`` of the joint kernel: ``h`` given, or (None) the optimal Gaussian-kernel
    bandwidth of the regularised particle filter, ``h = A N^(−1/(d+4))``,
    ``A = (4/(d+2))^(1/(d+4))`` (Musso, Oudjane & Le Gland 2001, for an equally weighted
    sample of a d-dimensional Gaussian), and the Liu–West shrinkage ``a = √(1 − h²)``."""
    if h is None:
        h = (4.0 / (d + 2.0)) ** (1.0 / (d + 4.0)) * float(N) ** (-1.0 / (d + 4.0))
    h = float(h)
    if not 0.0 <= h < 1.0:
        raise ValueError(f"kernel_bandwidth must lie in [0, 1), got {h}")
    return float(np.sqrt(1.0 - h * h)), h


def _joint_applies(dp, max_spread_rad):
    """True when the resampled attitude cloud is compact enough for the joint kernel: the
    largest per-axis standard deviation of its GRP error ``dp`` (≈ rad for small angles, a = 1,
    f = 4) is below ``max_spread_rad``. A wide cloud is often multimodal (the symmetric-shape
    ambiguities of a cube), and shrinking it toward its mean would merge the modes."""
    return float(np.max(np.std(dp, axis=0))) < max_spread_rad


def _joint_kernel(ops, Q, W, ext, qref, dp, rng, kern):
    """Liu–West (2001) shrinkage kernel on the full resampled state ``x = [δp, ω, e]``.

    ``x_i ← a x_i + (1 − a) x̄ + h L ε_i``, ``ε_i ~ N(0, I)``, with ``L Lᵀ`` the
    equal-weight covariance of the resampled cloud (δp the GRP about ``qref``, e the extra
    states) and ``kern = (a, h)``, ``a = √(1 − h²)`` (:func:`_joint_bandwidth`). Mean and
    covariance, including the attitude–rate–parameter cross-covariances, are kept in
    expectation; every component (also the rate, which the controlled dynamics never
    perturbs) is spread again (module docstring, "Rejuvenation of the combined state"). L is
    formed in standardised coordinates (correlation matrix), since the components' scales
    differ by ~10⁴.
    """
    a, h = kern
    if h == 0.0:
        return Q, W
    X = np.ascontiguousarray(np.hstack([dp, W, ext.E]))
    mean, C = K.mean_cov_nb(X)
    sd = np.sqrt(np.clip(np.diag(C), 0.0, None))
    live = sd > 0.0
    L = np.zeros((X.shape[1], 0))
    if np.any(live):
        Cl = C[np.ix_(live, live)] / np.outer(sd[live], sd[live])
        try:                 # Cholesky: ~20× cheaper than eigh for d = 30 on a busy machine
            Ll = sd[live][:, None] * np.linalg.cholesky(Cl)
        except np.linalg.LinAlgError:       # singular (e.g. a collapsed component)
            Ll = sd[live][:, None] * psd_sqrt(Cl)
        L = np.zeros((X.shape[1], Ll.shape[1]))
        L[live] = Ll
    eps = rng.standard_normal((X.shape[0], L.shape[1]))
    out = np.empty_like(X)
    K.affine_rows_nb(eps, np.ascontiguousarray(h * L), a, (1.0 - a) * mean, X, out)
    ext.E = np.ascontiguousarray(out[:, 6:])
    return (np.ascontiguousarray(ops.from_grp(np.ascontiguousarray(out[:, :3]), qref)),
            np.ascontiguousarray(out[:, 3:6]))


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
