"""Global attitude initialisation: from a uniform attitude prior to the user's filter.

Problem
-------
Every attitude filter needs a first guess; on a real recording there is none. The unknowns at
the first epoch are the attitude q₀ (inertial→body, scalar first) and the body rate ω₀. Over a
window of epochs the dynamics model of the lightcurve (controlled: constant body rate;
uncontrolled: torque-free Euler equations, the filters' own ``dynamics.propagate``) maps
θ = (q₀, ω₀) to a predicted magnitude history, so the window's magnitudes give a likelihood
L(θ) and the posterior p(θ | y) ∝ p(θ) L(θ) is a distribution on SO(3) × R³ — sharply peaked,
and with several modes wherever the shape or the geometry cannot tell attitudes apart.

Prior
-----
q₀ uniform over SO(3) (Haar measure: normalised 4-D Gaussian vectors, Muller 1959 /
Marsaglia 1972); the rate direction uniform on the sphere; the rate magnitude from the spin
period analysis (:mod:`.period`): a mixture over the best period and its aliases (weights from
their BIC differences) and the integer multiples 2–4 of the best period (``RATE_PRIOR_MULTIPLES``:
the brightness may repeat several times per turn), with the synodic bound and the statistical
1σ as its width (:meth:`.period.PeriodResult.rate_candidates`), plus a broad
log-uniform component (weight ``broad_weight``) over the periods the sampling allows, so a wrong
period analysis can be outvoted by the data. Without a significant period the broad component
alone.

Sampler
-------
A sequential Monte Carlo sampler with adaptive tempering (Del Moral, Doucet & Jasra 2006,
JRSS B 68, 411; the progressive-correction idea of Oudjane & Musso applied to the static
initial state): particles from the prior; the target ``p(θ) L(θ)^β`` with β raised from 0 to 1
in steps chosen so that the effective sample size of the incremental weights is
``ess_fraction · N``; after each step systematic resampling and ``moves`` random-walk
Metropolis moves (q' = exp(δ) ⊗ q with δ ~ N(0, s_q² I), ω' = ω + N(0, s_ω² I); the Haar prior
is invariant under this symmetric move, so the acceptance ratio holds the likelihood and the
rate prior only), their scales adapted between stages towards 15–40 % acceptance. The residuals
enter through a Student-t density (``nu`` degrees of freedom) scaled by the file's 1σ, so that a
few epochs the deterministic window model cannot follow (ACS noise, glints) do not decide.

Modes and hand-over
-------------------
At β = 1 the particles are grouped into modes (greedy: the most likely unassigned particle
gathers every particle within ``mode_radius_deg`` of attitude and ``mode_rate_frac`` of relative
rate). Each mode with weight ≥ ``min_mode_weight`` starts the user's filter (MEKF, UKF or BPF,
:func:`lightcurve.filters.invert.invert`) at its mean (Markley et al. 2007 quaternion average)
with its spread, inflated, as the initial covariance; the filter runs over the whole lightcurve.
Mode weights are the particle fractions. When at least ``report_weight`` of the posterior lies
outside the heaviest mode, the result says so and lists the modes (up to ``max_modes``, each
with the filter run from it): an ambiguity is stated, never resolved by fiat.

Exact symmetry: before grouping, every particle is replaced by its equivalent under the shape's
exact rotation symmetries (:mod:`.symmetry`) nearest the most likely particle, so the copies of
one answer are one mode, stated "unique up to the shape's K rotation symmetries".

Rejected modes: each started filter is tested against the data (NIS and posterior residuals,
:meth:`lightcurve.filters.result.Estimate.consistency`). When the heaviest mode's filter fails,
the filter is also started from the next ``refine_modes`` candidates (the cloud's lighter
particle groups and the axis-group images of the heaviest mode, by window likelihood): the
sampler's window is thinned and its likelihood very narrow near specular glints, so its
heaviest mode is not always the one the whole lightcurve supports. Only the starts the data
accept are reported; when some were rejected the accepted ones are weighed by their filters'
prediction-error likelihood (Σ −½(νₖ²/Sₖ + ln 2πSₖ), the filter's evidence for the whole
lightcurve; Bar-Shalom, Li & Kirubarajan 2001 §5.4 for the innovation statistics), and more than
one accepted mode with weight ≥ ``report_weight`` is stated as an ambiguity. When no start is
accepted, the search restarts with a fresh, independent sampler (``restarts`` times at most, each
with ``restart_factor`` × the particles), and a result that the data still reject is flagged as
such. The failures this catches are exploration failures of one sampler (the cloud collapses on
a wrong mode with no particle near the truth), so independent repeats at the first attempt's
size are the cheap remedy: with a per-attempt success p the chance that all 1 + R attempts miss
is (1 − p)^(1+R).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..estimation.particles import systematic_resample
from .period import PeriodResult, analyse_period
from .symmetry import fold_to_reference, symmetry_quaternions

#: multiples k of the brightness period taken as spin-period candidates of the rate prior, each
#: at a quarter of the best period's weight (:meth:`.period.PeriodResult.rate_candidates`): a
#: faceted body's brightness may repeat 2, 3 or 4 times per turn (:mod:`.period`, step 3), and a
#: fit of the brightness alone prefers the shorter period when turns do not repeat exactly
RATE_PRIOR_MULTIPLES = (2, 3, 4)

__all__ = ["GlobalInitConfig", "GlobalMode", "GlobalResult", "global_initialise",
           "uniform_quaternions", "axis_group_quaternions"]


def axis_group_quaternions() -> np.ndarray:
    """The 24 proper rotations that map the body axes onto ± body axes (the octahedral group),
    as quaternions (24, 4), identity first."""
    mats = []
    import itertools

    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            R = np.zeros((3, 3))
            for i, j in enumerate(perm):
                R[i, j] = signs[i]
            if np.linalg.det(R) > 0:
                mats.append(R)
    mats.sort(key=lambda R: -np.trace(R))
    return np.array([rot.dcm_to_quat(R) for R in mats])


def uniform_quaternions(n, rng) -> np.ndarray:
    """n unit quaternions uniform over SO(3) (Haar): normalised 4-D standard normal vectors."""
    q = rng.standard_normal((int(n), 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q


@dataclass(frozen=True)
class GlobalInitConfig:
    """Settings of the global initialisation (module docstring).

    particles : int — SMC particles (default 20,000).
    moves : int — random-walk Metropolis moves per tempering stage.
    jumps : int — symmetry-jump Metropolis moves per stage: q' = g ⊗ q, ω' = R_g ω with g one
        of the 23 non-trivial rotations mapping body axes onto body axes, so the chain can cross
        between the near-symmetric modes of box-like and cylindrical shapes (a symmetric
        proposal: the group is closed under inversion).
    ess_fraction : float in (0, 1) — target ESS of each tempering step, fraction of N.
    max_stages : int — most tempering stages before giving up (flagged).
    window_epochs : int — most epochs in the sampler's window (thinned evenly beyond that).
    window_s : float or None — window length, s (default: the whole lightcurve).
    nu : float > 2 — Student-t degrees of freedom of the standardised residuals.
    broad_weight : float in [0, 1) — weight of the broad log-uniform rate-magnitude component.
    mode_radius_deg, mode_rate_frac : grouping radii of a mode (attitude angle, relative rate).
    min_mode_weight : float — modes lighter than this are not modes (stray particles).
    report_weight : float — the result is stated as ambiguous when at least this much posterior
        mass lies outside the heaviest mode (in other modes).
    max_modes : int — most modes listed and handed to the filter (heaviest first).
    refine_modes : int — K: when the filter from the heaviest mode is inconsistent with the
        data (NIS or residual test of :meth:`lightcurve.filters.result.Estimate.consistency`),
        the filter is also started from the K next candidates, best window likelihood first:
        the cloud's other particle groups (below ``min_mode_weight`` or beyond ``max_modes``)
        and the 23 axis-group images of the heaviest mode (the near-symmetric attitudes of
        box-like shapes, as for ``jumps``); the consistent ones are kept.
    restarts : int — when no started filter is consistent with the data, the search is
        repeated (a fresh sampler with ``restart_factor`` × the particles), at most this many
        times; the attempt with consistent modes (else the one whose best mode explains the
        window best) is kept.
    restart_factor : float ≥ 1 — particles of a restart, as a multiple of ``particles``.
    min_sigma_theta_deg, min_sigma_omega_deg_s : floors of the hand-over 1σ.
    inflate : float ≥ 1 — factor on the modes' 1σ spread for the hand-over covariance.
    """

    particles: int = 20_000
    moves: int = 3
    jumps: int = 1
    ess_fraction: float = 0.5
    max_stages: int = 400
    window_epochs: int = 150
    window_s: float | None = None
    nu: float = 4.0
    broad_weight: float = 0.1
    mode_radius_deg: float = 20.0
    mode_rate_frac: float = 0.2
    min_mode_weight: float = 0.01
    report_weight: float = 0.05
    max_modes: int = 6
    restarts: int = 3
    restart_factor: float = 1.0
    refine_modes: int = 4
    min_sigma_theta_deg: float = 2.0
    min_sigma_omega_deg_s: float = 0.05
    inflate: float = 2.0

    def __post_init__(self):
        chk = [("particles", self.particles, 100, 50_000_000), ("moves", self.moves, 0, 100),
               ("jumps", self.jumps, 0, 100),
               ("max_stages", self.max_stages, 1, 100_000),
               ("window_epochs", self.window_epochs, 5, 1_000_000),
               ("max_modes", self.max_modes, 1, 100), ("restarts", self.restarts, 0, 5),
               ("refine_modes", self.refine_modes, 0, 100)]
        for name, v, lo, hi in chk:
            if int(v) != v or not lo <= v <= hi:
                raise InputError("out of range", field=f"global.{name}", value=v,
                                 allowed=f"integer in [{lo}, {hi}]")
        fl = [("ess_fraction", self.ess_fraction, 0.05, 0.95), ("nu", self.nu, 2.01, 1e6),
              ("broad_weight", self.broad_weight, 0.0, 0.99),
              ("mode_radius_deg", self.mode_radius_deg, 0.1, 180.0),
              ("mode_rate_frac", self.mode_rate_frac, 0.001, 10.0),
              ("min_mode_weight", self.min_mode_weight, 0.0, 1.0),
              ("report_weight", self.report_weight, 0.0, 1.0),
              ("min_sigma_theta_deg", self.min_sigma_theta_deg, 1e-3, 180.0),
              ("min_sigma_omega_deg_s", self.min_sigma_omega_deg_s, 1e-6, 100.0),
              ("inflate", self.inflate, 1.0, 100.0),
              ("restart_factor", self.restart_factor, 1.0, 16.0)]
        for name, v, lo, hi in fl:
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise InputError("out of range", field=f"global.{name}", value=v,
                                 allowed=f"[{lo}, {hi}]")
        if self.window_s is not None and not (math.isfinite(self.window_s) and self.window_s > 0):
            raise InputError("must be > 0", field="global.window_s", value=self.window_s)


@dataclass
class GlobalMode:
    """One posterior mode of the initial state and the filter run started from it.

    weight : posterior probability of the mode (particle fraction at β = 1).
    q0, omega0_rad_s : mode mean at the first epoch (inertial→body; rad/s body axes).
    att_sigma_deg, omega_sigma_deg_s : 1σ spread of the mode (body axes).
    best_loglik : window log-likelihood of the mode's best particle.
    estimate : the filter's Estimate from this mode (None if the mode started no filter).
    separation_deg : attitude angle between this mode's mean and the best mode's mean at t₀.
    source : "sampler" (a mode of the sampler's cloud), "cloud" (a lighter particle group,
        refined because the heaviest mode was rejected) or "image" (an axis-group image of
        the heaviest mode, likewise).
    sampler_weight : the particle fraction of the mode (0 for an image).
    consistent : the filter from this mode passed the NIS and residual tests (None: not run).
    filter_loglik : the filter's prediction-error log-likelihood of the whole lightcurve,
        Σ −½(νₖ²/Sₖ + ln 2πSₖ) over its updates (the evidence that weighs consistent modes).
    symmetries : number of exact rotation symmetries of the shape (the mode stands for that
        many attitudes, :mod:`.symmetry`).
    """

    weight: float
    q0: np.ndarray
    omega0_rad_s: np.ndarray
    att_sigma_deg: np.ndarray
    omega_sigma_deg_s: np.ndarray
    best_loglik: float
    separation_deg: float = 0.0
    estimate: object = None
    source: str = "sampler"
    sampler_weight: float | None = None
    consistent: bool | None = None
    filter_loglik: float | None = None
    symmetries: int = 1

    def summary(self) -> dict:
        d = {"weight": float(self.weight), "q0": [float(x) for x in self.q0],
             "source": self.source,
             "sampler_weight": float(self.weight if self.sampler_weight is None
                                     else self.sampler_weight),
             "consistent": self.consistent, "filter_loglik": self.filter_loglik,
             "symmetries": int(self.symmetries),
             "omega0_deg_s": [float(x) for x in np.degrees(self.omega0_rad_s)],
             "spin_period_s": float(2 * math.pi / max(np.linalg.norm(self.omega0_rad_s), 1e-300)),
             "att_sigma_deg": [float(x) for x in self.att_sigma_deg],
             "omega_sigma_deg_s": [float(x) for x in self.omega_sigma_deg_s],
             "best_window_loglik": float(self.best_loglik),
             "separation_from_best_deg": float(self.separation_deg)}
        if self.estimate is not None:
            e = self.estimate
            d["final_q"] = [float(x) for x in e.q[-1]]
            d["final_omega_deg_s"] = [float(x) for x in np.degrees(e.omega_rad_s[-1])]
            d["final_3sigma_att_deg"] = [float(x) for x in 3 * e.att_sigma_deg[-1]]
            d["diverged"] = bool(e.diverged)
            if e.att_error_deg is not None:
                d["final_att_error_rss_deg"] = float(np.linalg.norm(e.att_error_deg[-1]))
        return d


@dataclass
class GlobalResult:
    """Outcome of :func:`global_initialise`.

    modes : list of GlobalMode, heaviest first (at most ``max_modes``, each ≥ min_mode_weight).
    best : the Estimate of the heaviest mode's filter run.
    ambiguous : True when ≥ ``report_weight`` of the posterior lies outside the heaviest mode.
    n_modes_total : modes holding ≥ ``min_mode_weight`` (``modes`` lists at most ``max_modes``).
    statement : one sentence for people (what the data say about the attitude).
    period : the PeriodResult that seeded the rate prior (or None).
    stages, particles, runtime_s, window_rows : sampler facts of the kept attempt; ``converged``
    False when β did not reach 1 within ``max_stages``; ``attempts`` = 1 + restarts made.
    symmetries : exact rotation symmetries of the shape (1: none but the identity); each mode
        stands for that many attitudes giving the same lightcurve.
    n_rejected : started filters that the data reject (inconsistent), left out of ``modes``
        whenever at least one started filter is consistent.
    n_refined : extra candidates refined because the heaviest mode was rejected.
    """

    modes: list
    best: object
    ambiguous: bool
    statement: str
    period: PeriodResult | None
    stages: int
    particles: int
    runtime_s: float
    window_rows: np.ndarray = field(repr=False)
    converged: bool = True
    acceptance: list = field(default_factory=list, repr=False)
    attempts: int = 1
    n_modes_total: int = 1
    symmetries: int = 1
    n_rejected: int = 0
    n_refined: int = 0

    def summary(self) -> dict:
        return {"ambiguous": bool(self.ambiguous), "statement": self.statement,
                "n_modes": len(self.modes), "n_modes_total": int(self.n_modes_total),
                "symmetries": int(self.symmetries), "n_rejected": int(self.n_rejected),
                "n_refined": int(self.n_refined),
                "modes": [m.summary() for m in self.modes],
                "stages": int(self.stages), "particles": int(self.particles),
                "converged": bool(self.converged), "attempts": int(self.attempts),
                "runtime_s": round(float(self.runtime_s), 3),
                "window_epochs": int(self.window_rows.size),
                "period": None if self.period is None else self.period.summary()}


# ----------------------------------------------------------------------------------------
# rate-magnitude prior
# ----------------------------------------------------------------------------------------
class _RatePrior:
    """Mixture prior on |ω| (rad/s): Gaussian components from the period analysis plus a
    log-uniform component on [lo, hi]; the density of ω ∈ R³ is p(|ω|) / (4π|ω|²)."""

    def __init__(self, comps, lo, hi, broad_weight):
        self.lo, self.hi = float(lo), float(hi)
        self.mu = np.array([c[0] for c in comps], float)
        self.sd = np.array([c[1] for c in comps], float)
        w = np.array([c[2] for c in comps], float)
        if w.size:
            w = (1.0 - broad_weight) * w / w.sum()
            self.wb = float(broad_weight)
        else:
            self.wb = 1.0
        self.w = w

    def sample(self, n, rng):
        k = rng.random(n)
        r = np.empty(n)
        broad = k < self.wb
        nb = int(broad.sum())
        r[broad] = np.exp(rng.uniform(math.log(self.lo), math.log(self.hi), nb))
        if self.w.size and nb < n:
            idx = rng.choice(self.w.size, size=n - nb, p=self.w / self.w.sum())
            r[~broad] = np.abs(self.mu[idx] + self.sd[idx] * rng.standard_normal(n - nb))
        return r

    def logpdf_vec(self, W):
        """log density of ω vectors W (n,3) in R³ (up to a constant)."""
        r = np.linalg.norm(W, axis=1)
        with np.errstate(divide="ignore"):
            pb = np.where((r >= self.lo) & (r <= self.hi),
                          self.wb / (np.maximum(r, 1e-300) * math.log(self.hi / self.lo)), 0.0)
            p = pb.copy()
            for mu, sd, w in zip(self.mu, self.sd, self.w):
                # folded normal (|N(mu, sd)|)
                p += w * (np.exp(-0.5 * ((r - mu) / sd) ** 2)
                          + np.exp(-0.5 * ((r + mu) / sd) ** 2)) / (sd * math.sqrt(2 * math.pi))
            return np.log(p) - 2.0 * np.log(np.maximum(r, 1e-300))


def _rate_prior(period, span_s, dt_med, broad_weight):
    lo = 2.0 * math.pi / (20.0 * max(span_s, 1e-3))     # a twentieth of a turn in the window
    hi = 2.0 * math.pi / (2.0 * max(dt_med, 1e-6))      # Nyquist of the cadence
    comps = []
    if period is not None and period.significant:
        for c in period.rate_candidates(multiples=RATE_PRIOR_MULTIPLES):
            sd = math.sqrt(c["sigma_rad_s"] ** 2 + c["halfwidth_rad_s"] ** 2 / 3.0)
            comps.append((c["omega_rad_s"], max(sd, 1e-3 * c["omega_rad_s"]), c["weight"]))
    return _RatePrior(comps, lo, hi, broad_weight if comps else 1.0)


# ----------------------------------------------------------------------------------------
# likelihood over the window
# ----------------------------------------------------------------------------------------
class _Window:
    """The window's epochs and the vectorised Student-t log-likelihood of (q₀, ω₀) clouds."""

    #: largest RK4 sub-step of the window's torque-free propagation, s. The local error of an
    #: RK4 step of the kinematics is about (|ω|h)⁵/120 rad: 1.4e-6 rad at |ω| = 10 deg/s and
    #: h = 1 s — far below what a magnitude resolves — at half the filters' cost (0.5 s steps).
    SUBSTEP_S = 1.0

    def __init__(self, problem, rows, nu):
        self.model = problem.model
        self.dyn = problem.dynamics
        if self.dyn.kind == "uncontrolled" and self.dyn.substep < self.SUBSTEP_S:
            self.dyn = type(self.dyn)(self.dyn.J, substep_s=self.SUBSTEP_S)
        self.rows = np.asarray(rows, np.int64)
        self.t = np.ascontiguousarray(self.model.t, float)
        self.t_ref = float(self.t[0])
        self.y = np.ascontiguousarray(self.model.y, float)
        self.s = np.ascontiguousarray(self.model.sigma, float)
        self.nu = float(nu)
        self.zcap = 50.0
        self.n_evals = 0

    def loglik(self, Q0, W0):
        """Window log-likelihood (N,) of initial states Q0 (N,4), W0 (N,3) at the first epoch."""
        self.n_evals += Q0.shape[0]
        Q, W = Q0, W0
        tp = self.t_ref
        ll = np.zeros(Q0.shape[0])
        c = -(self.nu + 1.0) / 2.0
        for k in self.rows:
            Q, W = self.dyn.propagate(Q, W, float(self.t[k] - tp))
            tp = float(self.t[k])
            m = self.model.predict_q(Q, int(k))
            z = (self.y[k] - m) / self.s[k]
            z = np.where(np.isfinite(z), np.clip(z, -self.zcap, self.zcap), self.zcap)
            ll += c * np.log1p(z * z / self.nu)
        return ll


def _window_rows(model, cfg):
    """Finite-magnitude epochs inside the window, thinned evenly to ``window_epochs``."""
    t = np.asarray(model.t, float)
    fin = np.flatnonzero(np.isfinite(model.y))
    if cfg.window_s is not None:
        fin = fin[t[fin] <= t[0] + cfg.window_s]
    if fin.size > cfg.window_epochs:
        pick = np.unique(np.round(np.linspace(0, fin.size - 1, cfg.window_epochs)).astype(int))
        fin = fin[pick]
    return fin


def _next_beta(ll, beta, target):
    """Largest β' ∈ (β, 1] with ESS(exp((β'−β) ll)) ≥ target (bisection)."""
    def ess(b):
        a = (b - beta) * ll
        a = a - a.max()
        w = np.exp(a)
        return w.sum() ** 2 / np.sum(w * w)

    if ess(1.0) >= target:
        return 1.0
    lo, hi = beta, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if ess(mid) >= target:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12 * max(hi, 1e-300):
            break
    return max(lo, beta + 1e-12)


def _cluster(Q, W, ll, cfg):
    """Greedy grouping of the particles into modes → list of index arrays, heaviest first."""
    left = np.ones(Q.shape[0], bool)
    order = np.argsort(-ll)
    groups = []
    cos_r = math.cos(math.radians(cfg.mode_radius_deg) / 2.0)
    for i in order:
        if not left[i]:
            continue
        dot = np.abs(Q @ Q[i])
        wr = np.linalg.norm(W - W[i], axis=1) / max(np.linalg.norm(W[i]), 1e-12)
        mem = left & (dot >= cos_r) & (wr <= cfg.mode_rate_frac)
        mem[i] = True
        groups.append(np.flatnonzero(mem))
        left &= ~mem
        if not left.any():
            break
    groups.sort(key=lambda g: -g.size)
    return groups


def _smc(win, prior, N, cfg, rng, progress):
    """Tempered SMC over (q₀, ω₀) (module docstring) → Q, W, ll, stages, converged, β, acc."""
    Q = uniform_quaternions(N, rng)
    u = rng.standard_normal((N, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    W = u * prior.sample(N, rng)[:, None]
    ll = win.loglik(Q, W)
    lp = prior.logpdf_vec(W)
    beta, stages = 0.0, 0
    s_q = math.radians(30.0)
    s_w = 0.2
    acc_hist = []
    converged = True
    G = axis_group_quaternions()
    RG = rot.quat_to_dcm(G)
    while beta < 1.0:
        if stages >= cfg.max_stages:
            converged = False
            break
        nb = _next_beta(ll, beta, cfg.ess_fraction * N)
        a = (nb - beta) * ll
        a -= a.max()
        w = np.exp(a)
        w /= w.sum()
        idx = systematic_resample(w, rng)
        Q, W, ll, lp = Q[idx], W[idx], ll[idx], lp[idx]
        beta = nb
        stages += 1
        acc = []
        for _ in range(int(cfg.moves)):
            wn = np.linalg.norm(W, axis=1, keepdims=True)
            dq = rot.rotvec_to_quat(rng.standard_normal((N, 3)) * s_q)
            Qp = rot.quat_mult(dq, Q)
            Qp /= np.linalg.norm(Qp, axis=1, keepdims=True)
            Wp = W + rng.standard_normal((N, 3)) * (s_w * np.maximum(wn, 1e-6))
            llp = win.loglik(Qp, Wp)
            lpp = prior.logpdf_vec(Wp)
            # the proposal scale ∝ |ω| is not symmetric in ω: Hastings correction
            wnp = np.linalg.norm(Wp, axis=1)
            d2f = np.sum((Wp - W) ** 2, axis=1) / (s_w * np.maximum(wn[:, 0], 1e-6)) ** 2
            d2b = np.sum((W - Wp) ** 2, axis=1) / (s_w * np.maximum(wnp, 1e-6)) ** 2
            lq = (-0.5 * d2b - 3 * np.log(np.maximum(wnp, 1e-6))) - \
                 (-0.5 * d2f - 3 * np.log(np.maximum(wn[:, 0], 1e-6)))
            log_r = beta * (llp - ll) + (lpp - lp) + lq
            ok = np.log(rng.random(N)) < log_r
            Q[ok], W[ok], ll[ok], lp[ok] = Qp[ok], Wp[ok], llp[ok], lpp[ok]
            acc.append(float(ok.mean()))
        for _ in range(int(cfg.jumps)):
            gi = rng.integers(1, G.shape[0], N)
            Qp = rot.quat_mult(G[gi], Q)
            Qp /= np.linalg.norm(Qp, axis=1, keepdims=True)
            Wp = np.einsum("nij,nj->ni", RG[gi], W)
            llp = win.loglik(Qp, Wp)
            ok = np.log(rng.random(N)) < beta * (llp - ll)   # |ω| unchanged: prior ratio 1
            Q[ok], W[ok], ll[ok] = Qp[ok], Wp[ok], llp[ok]
        am = float(np.mean(acc)) if acc else 0.0
        acc_hist.append(am)
        if am < 0.15:
            s_q, s_w = s_q * 0.6, s_w * 0.6
        elif am > 0.4:
            s_q, s_w = min(s_q * 1.4, math.pi / 2), min(s_w * 1.4, 0.5)
        s_q = max(s_q, math.radians(0.02))
        s_w = max(s_w, 1e-5)
        if progress is not None:
            progress(f"stage {stages}: beta {beta:.3g}, acceptance {am:.2f}, "
                     f"step {math.degrees(s_q):.2g} deg")
    return Q, W, ll, stages, converged, beta, acc_hist


def _modes(Q, W, ll, cfg, gq=None):
    """Group the final cloud into modes → (list of GlobalMode (heaviest first, at most
    ``max_modes``), every group holding ≥ ``min_mode_weight``).

    ``gq`` (K, 4): the shape's exact rotation symmetries (:mod:`.symmetry`); every particle is
    first replaced by its symmetric equivalent nearest the most likely particle, so the K copies
    of a mode become one mode holding their summed weight."""
    N = Q.shape[0]
    if gq is not None and len(gq) > 1:
        Q, W, _ = fold_to_reference(Q, W, Q[int(np.argmax(ll))], gq)
    groups = _cluster(Q, W, ll, cfg)
    heavy = [g for g in groups if g.size / N >= cfg.min_mode_weight] or groups[:1]
    modes = []
    q_best = None
    for g in heavy[:cfg.max_modes]:
        qm = rot.quat_average(Q[g])
        dth = rot.attitude_error_rotvec(Q[g], np.broadcast_to(qm, Q[g].shape))
        wm = W[g].mean(axis=0)
        sa = np.degrees(dth.std(axis=0)) if g.size > 1 else np.zeros(3)
        sw = np.degrees(W[g].std(axis=0)) if g.size > 1 else np.zeros(3)
        if q_best is None:
            q_best = qm
        sep = float(np.degrees(2 * math.acos(min(1.0, abs(float(qm @ q_best))))))
        modes.append(GlobalMode(weight=g.size / N, q0=qm, omega0_rad_s=wm, att_sigma_deg=sa,
                                omega_sigma_deg_s=sw, best_loglik=float(ll[g].max()),
                                separation_deg=sep))
    return modes, heavy


def _hand_over(modes, cfg, run_filter):
    """Run the user's filter from every mode's mean with its inflated spread as 1σ; record
    whether the data accept it (no ``nis_high`` / ``residuals_high``) and its evidence."""
    for m in modes:
        st = max(cfg.inflate * float(m.att_sigma_deg.max()), cfg.min_sigma_theta_deg)
        sw_ = max(cfg.inflate * float(m.omega_sigma_deg_s.max()), cfg.min_sigma_omega_deg_s)
        m.estimate = run_filter(m.q0, m.omega0_rad_s, min(st, 90.0), sw_)
        m.estimate.meta["initial"] = "global"
        flags = m.estimate.consistency()["flags"]
        m.consistent = "nis_high" not in flags and "residuals_high" not in flags
        nu = np.asarray(m.estimate.innovations, float)
        S = np.asarray(m.estimate.innovation_var, float)
        ok = np.isfinite(nu) & np.isfinite(S) & (S > 0)
        m.filter_loglik = float(-0.5 * np.sum(nu[ok] ** 2 / S[ok] + np.log(2 * math.pi * S[ok])))


def _candidates(Q, W, ll, heavy, modes, win, cfg):
    """The next K starts when the heaviest mode is rejected (``refine_modes``): the cloud's
    particle groups not yet handed over (their best particle, their spread) and the axis-group
    images of the heaviest mode's best particle (that mode's spread), each at least
    ``mode_radius_deg`` from every start so far, best window likelihood first."""
    K = int(cfg.refine_modes)
    if K <= 0:
        return []
    groups = _cluster(Q, W, ll, cfg)
    cand = []
    for g in groups:
        i = g[int(np.argmax(ll[g]))]
        sa = np.degrees(rot.attitude_error_rotvec(
            Q[g], np.broadcast_to(Q[i], Q[g].shape)).std(axis=0)) if g.size > 1 else np.zeros(3)
        sw = np.degrees(W[g].std(axis=0)) if g.size > 1 else np.zeros(3)
        cand.append((float(ll[i]), Q[i], W[i], sa, sw, g.size / Q.shape[0], "cloud"))
    b = modes[0]
    G = axis_group_quaternions()[1:]
    RG = rot.quat_to_dcm(G)
    ib = int(np.argmax(ll))
    Qi = rot.quat_mult(G, np.broadcast_to(Q[ib], G.shape))
    Qi /= np.linalg.norm(Qi, axis=1, keepdims=True)
    Wi = np.einsum("nij,j->ni", RG, W[ib])
    lli = win.loglik(Qi, Wi)
    for k in range(G.shape[0]):
        cand.append((float(lli[k]), Qi[k], Wi[k], b.att_sigma_deg, b.omega_sigma_deg_s, 0.0,
                     "image"))
    cand.sort(key=lambda c: -c[0])
    cos_r = math.cos(math.radians(cfg.mode_radius_deg) / 2.0)
    taken = [m.q0 for m in modes]
    out = []
    for c in cand:
        if len(out) >= K:
            break
        if any(abs(float(c[1] @ q)) >= cos_r for q in taken):
            continue
        taken.append(c[1])
        out.append(GlobalMode(weight=0.0, q0=np.array(c[1]), omega0_rad_s=np.array(c[2]),
                              att_sigma_deg=np.asarray(c[3]), omega_sigma_deg_s=np.asarray(c[4]),
                              best_loglik=c[0], source=c[6], sampler_weight=c[5],
                              separation_deg=float(np.degrees(2 * math.acos(
                                  min(1.0, abs(float(c[1] @ b.q0))))))))
    return out


def _evidence_weights(modes):
    """Weights ∝ exp(filter_loglik) over ``modes`` (equal prior odds for each start)."""
    L = np.array([m.filter_loglik for m in modes], float)
    w = np.exp(L - L.max())
    return w / w.sum()


def global_initialise(curve, problem, run_filter, *, seed=0, config=None, period=None,
                      progress=None) -> GlobalResult:
    """Estimate attitude and rate from a lightcurve with no initial guess (module docstring).

    The user entry point is ``lightcurve.invert(curve, method, initial="global")``
    (:func:`lightcurve.filters.invert.invert`), which builds the two filter-side arguments.

    Parameters
    ----------
    curve : Lightcurve — the recording; its truth, if any, is never used by the estimator
        (only to report errors afterwards).
    problem : FilterProblem — the model (``problem.model``: magnitudes, times, geometry,
        ``predict_q``) and dynamics (``problem.dynamics.propagate``) of the filter that will take
        over; its initial estimate is not used.
    run_filter : callable(q0 (4,), omega0 (3,) rad/s, sigma_theta_deg, sigma_omega_deg_s) →
        Estimate — runs that filter over the whole lightcurve from a given start.
    seed : int — seeds the sampler (reproducible).
    config : GlobalInitConfig or None.
    period : PeriodResult, "none" or None — the spin-period analysis seeding the rate prior
        (None: computed here; "none": the broad prior only).
    progress : callable(str) or None — one line per tempering stage.

    Returns
    -------
    GlobalResult
    """
    cfg = config or GlobalInitConfig()
    t0 = time.perf_counter()
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x6C0B]))
    rows = _window_rows(problem.model, cfg)
    if rows.size < 5:
        raise InputError("global initialisation needs at least 5 finite magnitudes in the "
                         "window", field="mag", value=int(rows.size), allowed=">= 5")
    if period is None:
        try:
            period = analyse_period(curve)
        except InputError:
            period = None
    elif isinstance(period, str) and period == "none":
        period = None
    tt = np.asarray(problem.model.t, float)
    dts = np.diff(tt[rows])
    dt_med = float(np.median(dts[dts > 0])) if np.any(dts > 0) else 1.0
    span = float(tt[rows[-1]] - tt[0]) or 1.0
    prior = _rate_prior(period, span, dt_med, cfg.broad_weight)
    win = _Window(problem, rows, cfg.nu)

    shape = getattr(problem.model, "shape", None)
    gq = symmetry_quaternions(shape) if shape is not None else np.array([[1.0, 0, 0, 0]])
    n_sym = int(gq.shape[0])

    attempts = []
    for attempt in range(int(cfg.restarts) + 1):
        N = int(round(cfg.particles * (cfg.restart_factor if attempt else 1.0)))
        Q, W, ll, stages, converged, beta, acc_hist = _smc(win, prior, N, cfg, rng, progress)
        modes, heavy = _modes(Q, W, ll, cfg, gq)
        _hand_over(modes, cfg, run_filter)
        refined = []
        if not modes[0].consistent:
            refined = _candidates(Q, W, ll, heavy, modes, win, cfg)
            if progress is not None and refined:
                progress(f"the heaviest mode's filter is inconsistent with the data: starting "
                         f"it from {len(refined)} more candidates")
            _hand_over(refined, cfg, run_filter)
        started = modes + refined
        attempts.append((started, modes, heavy, N, stages, converged, beta, acc_hist,
                         len(refined)))
        if any(m.consistent for m in started):
            break
        if progress is not None and attempt < int(cfg.restarts):
            progress(f"no started filter is consistent with the data: restarting with "
                     f"{int(round(cfg.particles * cfg.restart_factor))} particles")
    # the attempt with consistent modes, else the one whose best mode explains the window best
    started, modes, heavy, N, stages, converged, beta, acc_hist, n_ref = max(
        attempts, key=lambda a: (any(m.consistent for m in a[0]), a[1][0].best_loglik))
    for m in started:
        m.symmetries = n_sym
        m.sampler_weight = m.weight if m.sampler_weight is None else m.sampler_weight
    good = [m for m in started if m.consistent]
    n_rejected = len(started) - len(good) if good else 0
    sym_txt = (f"; unique up to the shape's {n_sym} rotation symmetries (each mode stands for "
               f"{n_sym} attitudes that give the same lightcurve)" if n_sym > 1 else "")
    if good and (n_ref or n_rejected):
        # the data reject some starts: weigh the consistent ones by their filters' evidence
        for m, w in zip(good, _evidence_weights(good)):
            m.weight = float(w)
        good.sort(key=lambda m: -m.weight)
    if good:
        modes = good
    best = modes[0]
    for m in modes:
        m.separation_deg = float(np.degrees(2 * math.acos(min(1.0, abs(float(m.q0 @ best.q0))))))
    elsewhere = 1.0 - best.weight
    ambiguous = elsewhere >= cfg.report_weight and len(modes) > 1
    rej = (f"; {n_rejected} other start(s) rejected by the data (inconsistent fits)"
           if n_rejected else "")
    if ambiguous:
        more = len(heavy) - len(modes) if not n_ref and not n_rejected else 0
        parts = ", ".join(f"{m.weight:.0%} ({m.separation_deg:.0f} deg from the first)"
                          for m in modes)
        statement = (f"ambiguous: the lightcurve allows {len(modes)} attitude modes; the data "
                     f"cannot pick one. Listed: {parts}" + (f" (+{more} more not listed)"
                                                            if more > 0 else ""))
    else:
        statement = (f"one attitude mode ({best.weight:.0%} of the posterior); spin period "
                     f"{2 * math.pi / max(np.linalg.norm(best.omega0_rad_s), 1e-300):.4g} s")
    statement += sym_txt + rej
    if not converged:
        statement += f"; WARNING: the sampler stopped at beta {beta:.3g} < 1 (max_stages)"
    cons = best.estimate.consistency()
    if not cons["consistent"]:
        statement += ("; WARNING: the filter from the best mode is not consistent with the data "
                      f"({', '.join(cons['flags'])}) — treat this attitude as unconfirmed")
    res = GlobalResult(modes=modes, best=best.estimate, ambiguous=ambiguous,
                       statement=statement, period=period, stages=stages, particles=N,
                       runtime_s=time.perf_counter() - t0, window_rows=rows,
                       converged=converged, acceptance=acc_hist, attempts=len(attempts),
                       n_modes_total=len(heavy), symmetries=n_sym, n_rejected=n_rejected,
                       n_refined=n_ref)
    best.estimate.meta["global_init"] = res.summary()
    return res
