"""Bootstrap particle filter (BPF) on magnitudes (Bernard 2021 §7.3, tables 7.7–7.11).

Particles ``(q_i, ω_i)``: inertial→body quaternions (scalar first) and body rates (rad/s),
plus optional extra states (site biases, Model 3 facet parameters; Bernard ch. 8).

1. Initialisation (table 7.7): ``[δp_i, δω_i] ~ N(0, P₀)`` with δp a GRP (a = 1, f = 4);
   ``q_i = grp2q(δp_i) ⊗ q̂₀``, ``ω_i = ω̂₀ + δω_i``; log weights ``−log N``. A caller may
   give its own initial cloud instead (``initial_cloud``, e.g. attitudes uniform over SO(3)).
2. Propagation with the filter's dynamics (tables 7.7, 7.10): exact constant-rate step
   (controlled) or torque-free RK4 (uncontrolled), then a process-noise sample
   ``[δθ, δω] ~ N(0, Q_d)`` (η, pseudo-noise, and for the random-walk ACS model ζ, eq. 7.112).
   For the "jitter" ACS model ζ_i perturbs only the attitude used to predict the measurement.
3. Weights (table 7.8): ``log w_i += −½ ((y − m(q_i))/σ)²`` (m = +inf → −inf), normalised with
   log-sum-exp; ``N_eff = 1/Σ w_i²`` (eq. 6.61). Epochs with the object unlit or below the
   horizon are skipped; the robust variant gates outliers (:mod:`lightcurve.filters.gating`).
3b. Progressive correction (Oudjane & Musso 2000; robust variant): while the full likelihood
   would leave ``N_eff < ess_threshold · N`` it is applied as ``L^φ₁ L^φ₂ … (Σφ = 1)``, each φ
   the largest keeping ``N_eff`` at the threshold (bisection, or the faster bracketed root
   finder of ``BPFConfig.temper_solver``), each stage followed by
   resampling, a move of the attitude and a new prediction of the moved particles. If every
   weight is zero the weights are reset to uniform and the epoch is flagged
   (:data:`~lightcurve.filters.result.FLAG_COLLAPSE`; the run is reported as diverged).
4. Estimate (eq. 7.100–7.105): weighted GRP mean and covariance of ``[δp, ω]`` about a
   reference attitude q^(i) — the heaviest particle (thesis variant) or the heaviest particle
   refined once by the weighted GRP mean (robust) — and ``q̂ = grp2q(δp̄) ⊗ q^(i)``.
5. Resampling when ``N_eff < ess_threshold · N`` (multinomial, table 6.3, or systematic), then
   a rejuvenation move (:class:`BPFConfig` ``rejuvenation``): Table 7.9 roughening
   ``σ_l = 𝒢 E_l N^(−1/n)`` applied as ``q ← q(c_θ) ⊗ q`` (eq. 7.108) about the posterior
   estimate (``"table7.9"``); the same σ added in the GRP chart about the estimate's reference
   (``"separate"``, with the Liu–West jitter or Metropolis moves of the extra states); one
   Liu & West (2001) kernel on the full state ``[δp, ω, e]`` (``"joint"``); ``"auto"`` = joint
   while the resampled attitude cloud is compact (largest per-axis σ of its GRP error below
   ``joint_max_spread_deg``), else separate (a wide cloud is often multimodal and the kernel's
   shrinkage would merge the modes); ``"none"``.

Variants (DESIGN.md "Source variant and robust variant"): ``BPFConfig(variant="thesis")`` is the
plain bootstrap filter of Bernard ch. 7 — multinomial resampling (table 6.3), table 7.9
roughening, no progressive correction, no innovation gate, the estimate about the heaviest
particle. The text leaves the resampling threshold open (§6.3, "a matter of judgment and
tuning") and does not print 𝒢 (§9.1: tuned once per test setup): both are chosen once,
``ess_threshold = 0.5`` and ``𝒢 = 0.2``, for every case. ``variant="robust"`` (default) is the
progressive-correction filter with the joint kernel and the outlier gate. Measurements behind
these choices: docs/bpf.md.

Random numbers: every draw comes from :class:`_Draws` — by default counter-based
(Philox4x32-10, :mod:`lightcurve.core.particles`), drawn in parallel, a pure function of the
seed, the particle and the draw, so a run is reproducible bit for bit for a given seed on any
number of threads; ``rng="numpy"`` draws from one ``numpy.random.Generator`` in a fixed serial
order (the order of the earlier implementation, whose stored results the tests compare with).

Hot loops are ``numba.njit(parallel)`` kernels over particles
(:mod:`lightcurve.filters._bpf_kernels`, :mod:`lightcurve.core.particles`) on buffers allocated
once per run. :func:`run_bpf_numpy` is the same algorithm with the per-particle stages in plain
vectorised NumPy (the benchmark's reference; also used for shapes whose BRDFs have no kernel).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .. import rotations as rot
from ..core import particles as CP
from ..errors import InputError
from ..memory import check_allocation
from ..threads import limited_threads
from . import _bpf_kernels as BK
from ._common import GRP_A, GRP_F, FilterProblem, Recorder, attach_bias, psd_sqrt
from .config import VARIANTS, ConfigBase, register_filter_config
from .gating import InnovationGate
from .result import Estimate, FLAG_COLLAPSE, FLAG_NAN, FLAG_RESAMPLED

__all__ = ["BPFConfig", "run_bpf", "run_bpf_numpy", "VARIANTS", "REJUVENATIONS", "RESAMPLERS",
           "TEMPER_SOLVERS"]

RESAMPLERS = ("systematic", "multinomial")
REJUVENATIONS = ("auto", "joint", "separate", "table7.9", "none")
RNGS = ("philox", "numpy")
TEMPER_SOLVERS = ("bisection", "bracketed")

# variant → defaults of the fields left None (module docstring, "Variants")
_VARIANT_DEFAULTS = {
    "robust": dict(resampling="systematic", progressive=True, rejuvenation="auto", gating=True,
                   reference="refined"),
    "thesis": dict(resampling="multinomial", progressive=False, rejuvenation="table7.9",
                   gating=False, reference="heaviest"),
}


@register_filter_config
@dataclass(frozen=True)
class BPFConfig(ConfigBase):
    """Settings of one bootstrap particle filter (validated on construction; the particle
    filter's configuration object of :mod:`lightcurve.filters.config`).

    Fields left ``None`` take the defaults of ``variant`` (module docstring, "Variants"); a field
    given explicitly overrides the variant (a named departure, recorded in the Estimate's meta).

    Attributes
    ----------
    particles : int ≥ 2 — N.
    variant : {"robust", "thesis"}
    resampling : {"systematic", "multinomial"} (thesis: multinomial, table 6.3)
    ess_threshold : float in [0, 1] — resample when N_eff < ess_threshold · N.
    roughening : float ≥ 0 — 𝒢 of table 7.9 (0: no roughening).
    progressive : bool — progressive correction (module docstring, step 3b).
    max_stages : int ≥ 1 — most tempering stages per measurement.
    temper_solver : {"bisection", "bracketed"} — root finder of each stage's exponent:
        24 halvings of [0, rest] (the stored reference runs), or the octave bisection and
        Illinois regula falsi of :func:`lightcurve.core.particles.temper_exponent_bracketed`
        to 0.1 % of φ (≈ 10 N_eff evaluations instead of 24; other φ, so other runs; numba
        CPU backend only).
    rejuvenation : {"auto", "joint", "separate", "table7.9", "none"} (module docstring, step 5).
    kernel_bandwidth : float in [0, 1) or None — h of the joint kernel; None: the optimal
        Gaussian-kernel bandwidth ``(4/(d+2))^(1/(d+4)) N^(−1/(d+4))`` (Musso, Oudjane & Le
        Gland 2001).
    joint_max_spread_deg : float > 0 — largest per-axis σ (deg) of the resampled attitude
        cloud's GRP error for which "auto" uses the joint kernel.
    param_discount : float in (0, 1] — Liu–West discount δ of the extra states' jitter
        (separate rejuvenation; 1 disables it).
    mcmc_moves : int ≥ 0 or None — attitude-known Model 3 runs: Metropolis resample-move steps
        per resampling (None: 1 there, else 0).
    gating : bool — the outlier gate of :mod:`lightcurve.filters.gating` (False: none, as ch. 7;
        the gate's own settings are the problem's ``gate``).
    reference : {"refined", "heaviest"} — reference attitude of the estimate (step 4).
    rng : {"philox", "numpy"} — random-number source (module docstring).
    keep_clouds : tuple of int — epochs (negative from the end) at which to keep the error
        rotation vectors of ``cloud_size`` particles (needs truth; fig. 9.6-style plots).
    cloud_size : int ≥ 1
    device : {"cpu", "gpu"} — numba CPU kernels or the CUDA kernels of
        :mod:`lightcurve.filters.bpf_gpu`.
    """

    method: ClassVar[str] = "bpf"
    VARIANT_DEFAULTS: ClassVar[dict] = _VARIANT_DEFAULTS
    particles: int = 10_000
    variant: str = "robust"
    resampling: str | None = None
    ess_threshold: float = 0.5
    roughening: float = 0.2
    progressive: bool | None = None
    max_stages: int = 30
    temper_solver: str = "bisection"
    rejuvenation: str | None = None
    kernel_bandwidth: float | None = None
    joint_max_spread_deg: float = 25.0
    param_discount: float = 0.98
    mcmc_moves: int | None = None
    gating: bool | None = None
    reference: str | None = None
    rng: str = "philox"
    keep_clouds: tuple = ()
    cloud_size: int = 2000
    device: str = "cpu"

    def __post_init__(self):
        self._fill_variant_defaults()
        n = self.particles
        if isinstance(n, bool) or int(n) != n or n < 2:
            raise InputError(f"particles must be an integer >= 2, got {n}", field="particles")
        object.__setattr__(self, "particles", int(n))
        g = float(self.roughening)
        if not (g >= 0 and np.isfinite(g)):
            raise InputError(f"roughening must be finite and >= 0, got {self.roughening}",
                             field="roughening")
        if self.resampling not in RESAMPLERS:
            raise InputError(f"resampling must be one of {', '.join(RESAMPLERS)}, "
                             f"got {self.resampling!r}", field="resampling")
        if not 0.0 <= float(self.ess_threshold) <= 1.0:
            raise InputError(f"ess_threshold must lie in [0, 1], got {self.ess_threshold}",
                             field="ess_threshold")
        if int(self.max_stages) < 1:
            raise InputError(f"max_stages must be >= 1, got {self.max_stages}", field="max_stages")
        if self.temper_solver not in TEMPER_SOLVERS:
            raise InputError(f"temper_solver must be one of {', '.join(TEMPER_SOLVERS)}, "
                             f"got {self.temper_solver!r}", field="temper_solver")
        if self.rejuvenation not in REJUVENATIONS:
            raise InputError(f"rejuvenation must be one of {', '.join(map(repr, REJUVENATIONS))}, "
                             f"got {self.rejuvenation!r}", field="rejuvenation")
        h = self.kernel_bandwidth
        if h is not None and not 0.0 <= float(h) < 1.0:
            raise InputError(f"kernel_bandwidth must lie in [0, 1), got {h}",
                             field="kernel_bandwidth")
        if not float(self.joint_max_spread_deg) > 0.0:
            raise InputError(f"joint_max_spread_deg must be > 0, got {self.joint_max_spread_deg}",
                             field="joint_max_spread_deg")
        if not 0.0 < float(self.param_discount) <= 1.0:
            raise InputError(f"param_discount must lie in (0, 1], got {self.param_discount}",
                             field="param_discount")
        if self.mcmc_moves is not None and int(self.mcmc_moves) < 0:
            raise InputError(f"mcmc_moves must be >= 0, got {self.mcmc_moves}", field="mcmc_moves")
        if self.reference not in ("refined", "heaviest"):
            raise InputError(f"reference must be 'refined' or 'heaviest', got {self.reference!r}",
                             field="reference")
        if self.rng not in RNGS:
            raise InputError(f"rng must be one of {', '.join(RNGS)}, got {self.rng!r}",
                             field="rng")
        object.__setattr__(self, "keep_clouds", tuple(int(k) for k in self.keep_clouds))
        if int(self.cloud_size) < 1:
            raise InputError(f"cloud_size must be >= 1, got {self.cloud_size}", field="cloud_size")
        if self.device not in ("cpu", "gpu"):
            raise InputError(f"device must be 'cpu' or 'gpu', got {self.device!r}", field="device")

    @classmethod
    def thesis(cls, **kw) -> "BPFConfig":
        """The plain bootstrap filter of Bernard ch. 7 (module docstring, "Variants")."""
        return cls(variant="thesis", **kw)

    @classmethod
    def robust(cls, **kw) -> "BPFConfig":
        """Our default: progressive correction, joint kernel, outlier gate."""
        return cls(variant="robust", **kw)

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        return dataclasses.asdict(self)


class _Draws:
    """The random numbers of one run (module docstring, "Random numbers").

    ``normals_into(out)`` fills a C-contiguous (N, r) array with standard normals,
    ``uniform()`` returns one uniform, ``sorted_uniforms_into(u)`` fills ``u`` with ascending
    uniforms, ``normal(shape)`` / ``random(n)`` return new arrays (extra states).
    """

    def __init__(self, seed, kind):
        self.kind = kind
        if kind == "numpy":
            self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xB9F]))
        else:
            k = np.random.SeedSequence([int(seed), 0xB9F, 0x9417]).generate_state(2, np.uint32)
            self.k0, self.k1 = int(k[0]), int(k[1])
            self.call = 0
            self._one = np.empty(1)
            self._nbuf = np.empty(0)

    def normals_into(self, out):
        if out.size == 0:
            return out
        if self.kind == "numpy":
            self.rng.standard_normal(out=out)
        else:
            if self._nbuf.shape[0] < out.shape[0]:     # scratch, allocated once per run
                self._nbuf = np.empty(out.shape[0])
            CP.philox_normals_into(self.k0, self.k1, self.call, out, self._nbuf)
            self.call += 1
        return out

    def normal(self, shape):
        return self.normals_into(np.empty(shape))

    def uniform(self):
        if self.kind == "numpy":
            return float(self.rng.random())
        CP.philox_uniforms(self.k0, self.k1, self.call, self._one)
        self.call += 1
        return float(self._one[0])

    def random(self, n):
        if self.kind == "numpy":
            return self.rng.random(n)
        out = np.empty(n)
        CP.philox_uniforms(self.k0, self.k1, self.call, out)
        self.call += 1
        return out

    def sorted_uniforms_into(self, u):
        if self.kind == "numpy":
            self.rng.random(out=u)
        else:
            CP.philox_uniforms(self.k0, self.k1, self.call, u)
            self.call += 1
        u.sort()
        return u


def _flat(buf, n, r):
    """A C-contiguous (n, r) view of the first n·r entries of the 1-D buffer ``buf``."""
    return buf[:n * r].reshape(n, r)


PARTICLES_PER_THREAD = 16384
"""Smallest share of the cloud worth a numba thread of its own (see :func:`bpf_threads`)."""


def bpf_threads(particles: int) -> int:
    """Most numba threads the CPU filter uses for a cloud of ``particles``: one per
    :data:`PARTICLES_PER_THREAD` particles (at least one). A smaller share costs more in waking
    and joining the idle threads at each of the epoch's parallel stages than it saves, most of
    all on a busy machine (measurements: docs/bpf.md). The results do not depend on it: every
    draw and every reduction is fixed by the particle count alone."""
    return max(1, -(-int(particles) // PARTICLES_PER_THREAD))


def run_bpf(problem: FilterProblem, config: BPFConfig | None = None, *, seed=0, bias=None,
            facets=None, attitude="estimate", keep_clouds=None, cloud_size=None,
            initial_cloud=None, **overrides) -> Estimate:
    """Run the bootstrap particle filter (module docstring) with numba kernels → Estimate.

    Parameters
    ----------
    problem : FilterProblem
    config : BPFConfig, optional — the filter settings; ``overrides`` (any BPFConfig field,
        e.g. ``particles=2000, progressive=False``) replace fields of it (or of the default).
    seed : int — seeds every random draw (reproducible bit for bit).
    bias : :class:`lightcurve.filters.reflection.SiteBias` or None — per-site magnitude-bias
        states (random walk, Model 1, Model 2); the Estimate then carries ``bias`` and
        ``bias_sigma`` (N,S), mag.
    facets : :class:`lightcurve.filters.facet_states.FacetParameterStates` or None — Model 3
        facet-parameter states; the Estimate then carries ``refl_names``, ``refl_p`` /
        ``refl_p_sigma`` (weighted particle mean / standard deviation of p(z)) and ``refl_z``
        / ``refl_z_sigma`` per epoch (N,D).
    attitude : {"estimate", "truth"} — "truth" (or ``problem.attitude_known``) holds q and ω
        at the lightcurve's truth (§10.7 parameter-only runs) and estimates only the extra
        states.
    keep_clouds, cloud_size : override the configuration's (None: the configuration's).
    initial_cloud : (Q (N,4), W (N,3)) or None — start from these particles instead of the
        draw from ``P₀`` (N must equal ``particles``).
    """
    cfg = _config(config, overrides)
    if keep_clouds is not None or cloud_size is not None:
        cfg = cfg.replace(**{k: v for k, v in (("keep_clouds", keep_clouds),
                                               ("cloud_size", cloud_size)) if v is not None})
    if cfg.device == "gpu":
        from .bpf_gpu import run_bpf_gpu

        return run_bpf_gpu(problem, cfg, seed=seed, bias=bias, facets=facets,
                           attitude=attitude, initial_cloud=initial_cloud)
    backend = "numba" if problem.model.kernel_ok else "numpy"
    run = _Run(problem, cfg, seed, backend, bias, facets, attitude, cfg.keep_clouds,
               cfg.cloud_size, initial_cloud)
    with limited_threads(bpf_threads(cfg.particles)):
        return run.run()


def run_bpf_numpy(problem: FilterProblem, config: BPFConfig | None = None, *, seed=0,
                  bias=None, facets=None, attitude="estimate", initial_cloud=None,
                  **overrides) -> Estimate:
    """The same bootstrap particle filter with its per-particle stages in plain vectorised
    NumPy (the benchmark reference; :func:`run_bpf` for the arguments). With the same draws
    (``rng``) its results agree with :func:`run_bpf` to floating-point round-off."""
    cfg = _config(config, overrides)
    return _Run(problem, cfg, seed, "numpy", bias, facets, attitude, cfg.keep_clouds,
                cfg.cloud_size, initial_cloud).run()


def _config(config, overrides):
    if config is None:
        return BPFConfig(**overrides)
    if not isinstance(config, BPFConfig):
        raise TypeError(f"config must be a BPFConfig, got {type(config).__name__}")
    return config.replace(**overrides) if overrides else config


# --------------------------------------------------------------------------------------------
# NumPy versions of the per-particle stages (backend "numpy")
# --------------------------------------------------------------------------------------------

def _grp_rel_np(Q, qref):
    d = rot.quat_mult(Q, rot.quat_conj(qref)[None, :])
    d = np.where(d[:, :1] < 0, -d, d)
    return GRP_F * d[:, 1:] / (GRP_A + d[:, :1])


def _from_grp_np(P, qref):
    dq = rot.grp_to_quat(P, GRP_A, GRP_F)
    out = rot.quat_mult(dq, np.broadcast_to(qref, dq.shape))
    return out / np.linalg.norm(out, axis=1, keepdims=True)


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


def _temper_np(logw, ll, rest, target, steps):
    lo, hi = 0.0, rest
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if _ess_np(logw, ll, mid) >= target:
            lo = mid
        else:
            hi = mid
    return lo


def _wstats_np(X, w):
    mean = w @ X
    D = X - mean
    return mean, (D * w[:, None]).T @ D


class _HostOps:
    """Array handling shared by the two CPU backends (host NumPy arrays)."""

    @staticmethod
    def empty(shape, dtype=np.float64):
        return np.empty(shape, dtype=dtype)

    @staticmethod
    def full(shape, value):
        return np.full(shape, float(value))

    @staticmethod
    def from_host(a):
        return np.ascontiguousarray(a, dtype=np.float64).copy()

    @staticmethod
    def to_host(a):
        return a

    @staticmethod
    def fill(a, value):
        a[...] = value

    @staticmethod
    def row(a, i):
        return a[i].copy()

    @staticmethod
    def scale(a, f):
        a *= f

    @staticmethod
    def normals(draws, out):
        return draws.normals_into(out)

    systematic = staticmethod(CP.systematic_resample_into)
    sorted_merge = staticmethod(CP.sorted_resample_into)

    @staticmethod
    def ranges(Xc):
        E = np.empty(Xc.shape[1])
        CP.column_ranges(Xc, E)
        return E


class _NumbaOps(_HostOps):
    """Stages of the filter on numba kernels (in place on the run's buffers)."""

    gather = staticmethod(CP.gather_rows)
    mean_cov = staticmethod(CP.mean_cov_rows)

    @staticmethod
    def predict(run, k, dt, z, L, zeta, s):
        """Propagate the cloud over dt (process noise z Lᵀ) and, for finite s, predict the
        magnitudes of epoch k into ``run.mpred`` (module docstring, step 2)."""
        m = run.p.model
        n_arr, a_arr, ids, prm = m._karrs
        BK.bpf_predict_nb(run.Q, run.W, dt, run.mode, run.J, run.Ji,
                          run.p.dynamics.nsub(dt) if (run.mode and dt != 0.0) else 1, z, L,
                          zeta, s, m.o_eci[k], n_arr, a_arr, ids, prm, float(m.offset[k]),
                          run.mpred, run.dq, run.dq_mode(zeta), run.pwork)

    innov = staticmethod(CP.innovation_loglik)

    @staticmethod
    def loglik(logw, mpred, y, sig, ll):
        """The log-likelihoods of ``innov`` alone (its moments are not needed)."""
        CP.gaussian_loglik_into(mpred, y, sig, ll)
    addnorm = staticmethod(CP.add_loglik_normalize)
    ess = staticmethod(CP.ess_tempered)
    temper = staticmethod(CP.temper_exponent)
    argmax = staticmethod(BK.argmax_weights)

    @staticmethod
    def temper_bracketed(logw, ll, rest, target):
        """The exponent of :func:`~lightcurve.core.particles.temper_exponent_bracketed`
        (relative precision 1e-3, at most 40 N_eff evaluations)."""
        return CP.temper_exponent_bracketed(logw, ll, rest, target, 1e-3, 40)
    wstats = staticmethod(CP.weighted_mean_cov_rows)
    nearest = staticmethod(BK.min_abs_residual)

    @staticmethod
    def grp_mean(Q, qref, w):
        return BK.grp_weighted_mean(Q, qref, w, GRP_A, GRP_F)

    @staticmethod
    def chart(Q, W, qref, X):
        BK.chart_rows(Q, W, qref, GRP_A, GRP_F, X)

    @staticmethod
    def chart_stats(Q, W, w, qref, w0, X):
        return BK.chart_stats(Q, W, w, qref, GRP_A, GRP_F, w0, X)

    @staticmethod
    def roughen_chart(X, z, sig, ncols, qref, Q, W):
        BK.roughen_chart(X, z, sig, ncols, qref, GRP_A, GRP_F, Q, W)

    @staticmethod
    def roughen_compose(Q, W, z, sig):
        BK.roughen_compose(Q, W, z, sig, GRP_A, GRP_F)

    @staticmethod
    def liu_west(X, eps, M, sa, c, qref, Q, W, E):
        BK.liu_west_attitude(X, eps, M, sa, c, qref, GRP_A, GRP_F, Q, W, E)


class _NumpyOps(_HostOps):
    """The same stages in plain NumPy (new arrays, copied into the run's buffers)."""

    @staticmethod
    def gather(src, idx, dst):
        dst[:] = src[idx]

    @staticmethod
    def mean_cov(X):
        mean = X.mean(axis=0)
        D = X - mean
        return mean, D.T @ D / X.shape[0]

    @staticmethod
    def predict(run, k, dt, z, L, zeta, s):
        Qn, Wn = _propagate_np(run.p.dynamics, run.Q, run.W, dt)
        if z.shape[0]:
            noise = z @ L.T
            Qn = rot.quat_mult(rot.rotvec_to_quat(noise[:, :3]), Qn)
            Qn = Qn / np.linalg.norm(Qn, axis=1, keepdims=True)
            Wn = Wn + noise[:, 3:]
        run.Q[:] = Qn
        run.W[:] = Wn
        if not np.isnan(s[0]):
            Qm = run.Q
            if zeta.shape[0]:
                Qm = rot.quat_mult(rot.rotvec_to_quat(zeta), Qm)
            run.mpred[:] = _predict_np(run.p.model, Qm, k)

    innov = staticmethod(_innov_np)

    @staticmethod
    def loglik(logw, mpred, y, sig, ll):
        _innov_np(logw, mpred, y, sig, ll)
    addnorm = staticmethod(_addnorm_np)
    ess = staticmethod(_ess_np)
    temper = staticmethod(_temper_np)
    wstats = staticmethod(_wstats_np)

    @staticmethod
    def argmax(w):
        return int(np.argmax(w))

    @staticmethod
    def nearest(mpred, y):
        f = np.isfinite(mpred)
        return float(np.min(np.abs(y - mpred[f]))) if np.any(f) else np.inf

    @staticmethod
    def grp_mean(Q, qref, w):
        return w @ _grp_rel_np(Q, qref)

    @staticmethod
    def chart(Q, W, qref, X):
        X[:, :3] = _grp_rel_np(Q, qref)
        X[:, 3:6] = W

    @staticmethod
    def chart_stats(Q, W, w, qref, w0, X):
        _NumpyOps.chart(Q, W, qref, X)
        return _wstats_np(X[:, :6], w)

    @staticmethod
    def roughen_chart(X, z, sig, ncols, qref, Q, W):
        x = X[:, :ncols] + z * sig[None, :ncols]
        Q[:] = _from_grp_np(x[:, :3], qref)
        if ncols == 6:
            W[:] = x[:, 3:6]

    @staticmethod
    def roughen_compose(Q, W, z, sig):
        c = z[:, :sig.size] * sig[None, :z.shape[1]]
        Qn = rot.quat_mult(rot.grp_to_quat(c[:, :3], GRP_A, GRP_F), Q)
        Q[:] = Qn / np.linalg.norm(Qn, axis=1, keepdims=True)
        if c.shape[1] >= 6:
            W += c[:, 3:6]

    @staticmethod
    def liu_west(X, eps, M, sa, c, qref, Q, W, E):
        x = sa * X + c[None, :] + eps @ M.T
        Q[:] = _from_grp_np(x[:, :3], qref)
        W[:] = x[:, 3:6]
        E[:] = x[:, 6:]


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
            self.E = rng.normal((N, self.ne)) * np.sqrt(bias.var0)[None, :]
        elif self.kind == "facets":
            self.ne = facets.dim
            L0 = np.linalg.cholesky(facets.P0)
            self.E = facets.z0[None, :] + rng.normal((N, self.ne)) @ L0.T
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
                self.E += rng.normal(self.E.shape) * np.sqrt(qb)[None, :]
        else:
            qz = self.facets.process_noise * abs(dt)
            if qz > 0.0:
                self.E += rng.normal(self.E.shape) * np.sqrt(qz)

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
        mean, V = CP.mean_cov_rows(self.E)
        L = psd_sqrt(V)
        if not L.shape[1]:
            return
        eps = rng.normal((self.E.shape[0], L.shape[1]))
        out = np.empty_like(self.E)
        CP.liu_west_rows(eps, np.ascontiguousarray(self.h * L), self.a, (1.0 - self.a) * mean,
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
        BK.facet_loglik_history_nb(Z, k, phi, Qs, S, O, offs, y, sig, self.fc, self.kc,
                                  self.lg, n_arr, self.areas0, ids, self.params0, ll)
        r = np.empty_like(Z)
        CP.liu_west_rows(Z, self._Linv, 0.0, -(self._Linv @ self.facets.z0), Z, r)
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
        L = psd_sqrt(CP.mean_cov_rows(self.E)[1])
        if not L.shape[1]:
            return
        cL = np.ascontiguousarray(2.38 / np.sqrt(D) * L)
        zero = np.zeros(D)
        lp0 = self._log_post(self.E, k, phi)
        for _ in range(self.n_moves):
            Zp = np.empty_like(self.E)
            CP.liu_west_rows(rng.normal((self.E.shape[0], L.shape[1])), cL, 1.0, zero,
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
            zm, zv, pm, pv = BK.weighted_param_stats_nb(self.E, np.ascontiguousarray(w), self.lg)
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
        BK.facet_mag_particles_nb(Q, zeta, ext.E, ext.fc, ext.kc, ext.lg, m.s_eci[k], m.o_eci[k],
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



# --------------------------------------------------------------------------------------------
# the filter run
# --------------------------------------------------------------------------------------------

class _Run:
    """One filter run: buffers allocated once, then one pass over the epochs (module
    docstring, steps 1–5)."""

    def __init__(self, p, cfg, seed, backend, bias, facets, attitude, keep_clouds, cloud_size,
                 initial_cloud):
        if bias is not None and facets is not None:
            raise ValueError("site biases and Model 3 facet states are alternatives; give one")
        if attitude not in ("estimate", "truth"):
            raise ValueError(f"attitude must be 'estimate' or 'truth', got {attitude!r}")
        fixed = attitude == "truth" or bool(getattr(p, "attitude_known", False))
        if fixed and (p.truth_q is None or p.truth_omega is None):
            raise InputError("attitude='truth' needs the truth attitude and rate in the "
                             "lightcurve", field="attitude", value=attitude)
        if fixed and cfg.rejuvenation == "joint":
            raise ValueError("rejuvenation='joint' needs the attitude estimated (attitude='truth' "
                             "holds q and ω at the truth; use 'separate' or mcmc_moves there)")
        self.p, self.cfg, self.seed, self.backend, self.fixed = p, cfg, int(seed), backend, fixed
        self.ops = _BACKENDS[backend]()
        if (cfg.progressive and cfg.temper_solver != "bisection"
                and not hasattr(self.ops, "temper_bracketed")):
            raise NotImplementedError(f"temper_solver={cfg.temper_solver!r} runs on the numba "
                                      f"CPU backend only (this run: {backend})")
        self.draws = _Draws(seed, cfg.rng)
        self.N = N = cfg.particles
        # the run's buffers: ≈ 32 + 3 (6 + e) doubles per particle (refused before allocating)
        ne = bias.n_sites if bias is not None else (facets.dim if facets is not None else 0)
        check_allocation(8 * N * (32 + 3 * (6 + ne)), "particle-filter buffers",
                         field="particles", value=N)
        self.keep = ({int(k) % p.n for k in keep_clouds}
                     if (p.truth_q is not None and not fixed) else set())
        self.cloud_size = int(cloud_size)
        self.rec = Recorder(p, "bpf")
        self.rec.stages = np.zeros(p.n, dtype=np.int64)
        self.gate = InnovationGate(p, auto="inflate")
        if not cfg.gating:
            self.gate.cfg = dataclasses.replace(self.gate.cfg, mode="off")
        dyn = p.dynamics
        self.mode = 0 if dyn.kind == "controlled" else 1
        self.J = np.ascontiguousarray(dyn.J if dyn.J is not None else np.eye(3))
        self.Ji = np.ascontiguousarray(dyn.J_inv if dyn.J_inv is not None else np.eye(3))
        self.thr = float(cfg.ess_threshold) * N
        self.G = float(cfg.roughening)
        # buffers (allocated once per run)
        ops = self.ops
        self.logw = ops.full(N, -np.log(N))
        self.w = ops.full(N, 1.0 / N)
        self.ll = ops.full(N, 0.0)
        self.mpred = ops.empty(N)
        self.mpred2 = None            # allocated when a stage keeps the copies' predictions
        self.C = ops.empty(N)
        self.idx = ops.empty(N, np.int64)
        nz = N if (p.jitter_zeta() and not fixed) else 0
        self.zeta = ops.empty((nz, 3))
        self.zeta2 = ops.empty((nz, 3))
        # exp(ζ_i) of the jitter, kept through the tempering stages' re-predictions (numba)
        self.dq = np.empty((nz if (backend == "numba" and cfg.progressive) else 0, 4))
        self.dq_ok = False
        # scratch of the vectorised prediction kernel (numba)
        self.pwork = np.empty(BK.predict_work_size(N) if backend == "numba" else 0)
        self.ubuf = np.empty(N) if cfg.resampling == "multinomial" else None
        self._init_cloud(initial_cloud)
        self.ext = _Extra(p, bias, facets, N, self.draws, cfg.param_discount)
        mm = cfg.mcmc_moves
        if mm is None:
            mm = 1 if (fixed and facets is not None) else 0
        self.ext.setup_moves(p, mm, self.tq if fixed else None)
        D = 6 + self.ext.ne
        self.X = ops.full((N, D), 0.0)
        self.X2 = ops.full((N, D), 0.0)
        # the resampled exp(ζ) of a stage go to X2's memory: X2 is not used between the
        # epoch's prediction and its end-of-epoch resampling, which sets dq_ok False
        self.dq2 = _flat(self.X2.reshape(-1), self.dq.shape[0], 4)
        # normals of the process noise, the roughening and the kernel moves (never at once)
        self.ebuf = ops.empty(N * max(D, 6))
        self.zbuf = self.ebuf
        self.joint = cfg.rejuvenation in ("auto", "joint") and not fixed
        self.kern = _joint_bandwidth(cfg.kernel_bandwidth, N, D) if self.joint else None
        self.spread = float(np.radians(cfg.joint_max_spread_deg))
        self.n_joint = 0
        self._empty6 = ops.empty((0, 6))
        self._zero6 = np.zeros((6, 6))
        self._noL = np.zeros((6, 0))

    def _init_cloud(self, initial_cloud):
        p, N = self.p, self.N
        if self.fixed:
            self.tq = p.truth_q / np.linalg.norm(p.truth_q, axis=1, keepdims=True)
            self.Q = np.ascontiguousarray(self.tq[:1])
            self.W = np.ascontiguousarray(p.truth_omega[:1])
            self.Q2, self.W2 = self.Q.copy(), self.W.copy()
            return
        if initial_cloud is not None:
            Q0 = np.asarray(initial_cloud[0], float)
            W0 = np.asarray(initial_cloud[1], float)
            if Q0.shape != (N, 4) or W0.shape != (N, 3):
                raise ValueError(f"initial_cloud must be (Q ({N},4), W ({N},3)), got "
                                 f"{Q0.shape}, {W0.shape}")
            if not (np.all(np.isfinite(Q0)) and np.all(np.isfinite(W0))):
                raise ValueError("initial_cloud contains NaN or inf")
            self.Q = np.ascontiguousarray(Q0 / np.linalg.norm(Q0, axis=1, keepdims=True))
            self.W = np.ascontiguousarray(W0).copy()
        else:
            X0 = self.draws.normal((N, 6)) @ psd_sqrt(p.P0).T
            P0 = np.ascontiguousarray(X0[:, :3])
            if self.backend != "numpy":
                self.Q = np.empty((N, 4))
                BK.grp_times_rows(P0, np.ascontiguousarray(p.q0, dtype=float), GRP_A, GRP_F,
                                  self.Q)
            else:
                self.Q = np.ascontiguousarray(_from_grp_np(P0, p.q0))
            self.W = np.ascontiguousarray(p.omega0[None, :] + X0[:, 3:])
        self.Q = self.ops.from_host(self.Q)
        self.W = self.ops.from_host(self.W)
        self.Q2 = self.ops.empty(self.Q.shape)
        self.W2 = self.ops.empty(self.W.shape)

    # ---------------------------------------------------------------------------------
    def run(self) -> Estimate:
        p, cfg, N, ops, rec, gate, ext = (self.p, self.cfg, self.N, self.ops, self.rec,
                                          self.gate, self.ext)
        m, dyn = p.model, p.dynamics
        t0 = time.perf_counter()
        clouds = {}
        w_mean = p.omega0.copy() if not self.fixed else p.truth_omega[0].copy()
        empty6 = ops.empty((0, 6))
        empty3 = ops.empty((0, 3))
        nan3 = np.full(3, np.nan)
        zero6 = np.zeros((6, 6))
        for k in range(p.n):
            dt = float(m.t[k] - m.t[k - 1]) if k > 0 else 0.0
            z = empty6
            L = zero6
            if dt != 0.0 and not self.fixed:
                _, Qd = dyn.transition(w_mean, dt)
                if p.random_walk_zeta():
                    Qd = Qd.copy()
                    Qd[:3, :3] += dyn.zeta_cov
                # no process noise (Q_d = 0): psd_sqrt's (6, 0) without its eigh
                L = np.ascontiguousarray(psd_sqrt(Qd)) if Qd.any() else self._noL
                if L.shape[1]:
                    z = ops.normals(self.draws, _flat(self.zbuf, N, L.shape[1]))
            y = m.y[k]
            has_y = bool(np.isfinite(y))
            skipped = has_y and gate.skip_epoch(k, rec)   # object unlit / below the horizon
            has_y = has_y and not skipped
            zeta = empty3
            if has_y and p.jitter_zeta() and not self.fixed:
                zeta = ops.normals(self.draws, self.zeta)
                ops.scale(zeta, dyn.acs_sigma)
                self.dq_ok = False
            ext.propagate(dt, w_mean, self.draws)
            mpred = self.mpred
            if self.fixed:
                self.Q = np.ascontiguousarray(self.tq[k:k + 1])
                self.W = np.ascontiguousarray(p.truth_omega[k:k + 1])
                if has_y:
                    self._predict(k, zeta)
            else:
                s = m.s_eci[k] if (has_y and ext.kind != "facets") else nan3
                ops.predict(self, k, dt, z, L, zeta, s)
                if has_y and ext.kind == "facets":
                    _predict_facets(self.backend, p, ext, k, self.Q, zeta, mpred)
                elif has_y:
                    ext.add_bias(mpred, k)
            if skipped:
                neff, _ = ops.addnorm(self.logw, self.ll, 0.0, self.w)
            elif not has_y:
                rec.flags[k] |= FLAG_NAN
                rec.skipped_nan += 1
                neff, _ = ops.addnorm(self.logw, self.ll, 0.0, self.w)
            else:
                neff, zeta = self._update(k, float(y), zeta)
            rec.neff[k] = neff
            if self.fixed:
                qhat, what, Cov = self.tq[k], p.truth_omega[k].copy(), zero6
            else:
                qhat, what, Cov, qref = self._estimate(self.w)
            ext.record(k, self.w)
            if k in self.keep:
                clouds[k] = self._cloud(k)
            w_mean = what
            rec.store(k, qhat, what, Cov)
            if has_y and neff < self.thr:
                self._resample_move(k, None if self.fixed else qref, qhat)
        est = gate.finish(rec.finish(time.perf_counter() - t0))
        est.meta["tempering_stages"] = rec.stages.tolist()
        est.meta["bpf"] = dict(cfg.as_dict(), backend=self.backend)
        if self.fixed:
            est.meta["attitude"] = "truth"
        ext.attach(est)
        if self.joint:
            est.meta["rejuvenation"] = {"kind": "joint", "bandwidth_h": self.kern[1],
                                        "shrinkage_a": self.kern[0], "dimension": 6 + ext.ne,
                                        "max_spread_deg": float(cfg.joint_max_spread_deg),
                                        "joint_applied": self.n_joint}
            if ext.kind is not None:
                est.meta["reflection"]["roughening"] = "joint-liu-west"
        est.clouds = clouds or None
        return est

    # ---------------------------------------------------------------------------------
    def _predict(self, k, zeta):
        """Predicted magnitudes of the current cloud at epoch k into ``self.mpred``."""
        if self.fixed or self.ext.kind is not None:
            _predict_any(self.backend, self.p, self.ext, k, self.Q, self.W, zeta, self.J,
                         self.Ji, self.mpred)
        else:
            self.ops.predict(self, k, 0.0, self._empty6, self._zero6, zeta, self.p.model.s_eci[k])

    def dq_mode(self, zeta):
        """``dq_mode`` of :func:`~lightcurve.filters._bpf_kernels.bpf_predict_nb` for a
        prediction with the jitter ``zeta``: 0 (no ζ, or nothing keeps exp(ζ)), 1 (form
        exp(ζ_i) and keep them in ``self.dq``), 2 (read them: the same ζ, resampled with the
        cloud since)."""
        if not (zeta.shape[0] and self.dq.shape[0]):
            return 0
        if self.dq_ok:
            return 2
        self.dq_ok = True
        return 1

    def _update(self, k, y, zeta):
        """Measurement update of epoch k (steps 3, 3b) → (N_eff, ζ after resamplings)."""
        p, cfg, ops, rec, gate, N = self.p, self.cfg, self.ops, self.rec, self.gate, self.N
        logw, ll, w, mpred = self.logw, self.ll, self.w, self.mpred
        sig = float(p.model.sigma[k])
        yhat, var_m, any_fin = ops.innov(logw, mpred, y, sig, ll)
        # innovation gate: S = particle variance of the predictions + R (gating.py)
        R = (gate.check(k, y - yhat, var_m + sig * sig, sig * sig, rec,
                        nu_nearest=ops.nearest(mpred, y)) if any_fin else sig * sig)
        if R is None:
            ops.fill(ll, 0.0)   # outlier rejected: the weights are left unchanged
        elif R != sig * sig:
            sig = float(np.sqrt(R))   # gate mode "inflate": the inflated noise
            ops.loglik(logw, mpred, y, sig, ll)
        if any_fin and R is not None:
            rec.innovation(k, y - yhat, var_m + sig * sig)
        rest = 1.0
        if cfg.progressive:
            for _stage in range(int(cfg.max_stages)):
                if ops.ess(logw, ll, rest) >= self.thr:
                    break
                if cfg.temper_solver == "bisection":
                    phi = ops.temper(logw, ll, rest, self.thr, 24)
                else:
                    phi = ops.temper_bracketed(logw, ll, rest, self.thr)
                if not phi > 0.0:
                    break
                _, ok = ops.addnorm(logw, ll, phi, w)
                if not ok:
                    break
                rest -= phi
                zeta, moved = self._stage_move(k, rest, zeta)
                if moved:
                    self._predict(k, zeta)
                else:     # no particle moved: the copies keep their predictions
                    if self.mpred2 is None:
                        self.mpred2 = ops.empty(N)
                    ops.gather(mpred.reshape(N, 1), self.idx, self.mpred2.reshape(N, 1))
                    self.mpred, self.mpred2 = self.mpred2, self.mpred
                    mpred = self.mpred
                ops.loglik(logw, mpred, y, sig, ll)
                rec.stages[k] += 1
        neff, ok = ops.addnorm(logw, ll, rest, w)
        if not ok:
            rec.flags[k] |= FLAG_COLLAPSE
            ops.fill(logw, -np.log(N))
            neff, _ = ops.addnorm(logw, ll, 0.0, w)
        return neff, zeta

    def _resample(self):
        """Resampling indices into ``self.idx`` from the weights ``self.w`` (False: all zero)."""
        if self.cfg.resampling == "systematic":
            return self.ops.systematic(self.w, self.draws.uniform(), self.C, self.idx)
        u = self.draws.sorted_uniforms_into(self.ubuf)
        return self.ops.sorted_merge(self.w, u, self.C, self.idx)

    def _gather_qw(self):
        """Q, W ← Q[idx], W[idx] (double buffers swapped)."""
        self.ops.gather(self.Q, self.idx, self.Q2)
        self.ops.gather(self.W, self.idx, self.W2)
        self.Q, self.Q2 = self.Q2, self.Q
        self.W, self.W2 = self.W2, self.W

    def _reset_weights(self, k):
        self.ops.fill(self.logw, -np.log(self.N))
        self.rec.flags[k] |= FLAG_RESAMPLED

    def _stage_move(self, k, rest, zeta):
        """Resampling and attitude move between tempering stages (step 3b) → (ζ resampled,
        whether any particle moved: without a move the copies keep their predictions)."""
        ext, cfg = self.ext, self.cfg
        self._resample()
        if not self.fixed:
            self._gather_qw()
        ext.take(self.idx)
        if zeta.shape[0]:
            self.ops.gather(zeta, self.idx, self.zeta2)
            self.zeta, self.zeta2 = self.zeta2, self.zeta
            zeta = self.zeta
            if self.dq_ok:
                self.ops.gather(self.dq, self.idx, self.dq2)
                self.dq, self.dq2 = self.dq2, self.dq
        self._reset_weights(k)
        rej = cfg.rejuvenation
        if self.fixed:
            self._move_extras(k, 1.0 - rest)
            return zeta, True
        if not self.joint and not ext.ne and (rej == "none" or not self.G > 0.0):
            return zeta, False
        self.ops.fill(self.w, 1.0 / self.N)
        _, _, _, qst = self._estimate(self.w)
        if ext.ne:
            self.X[:, 6:] = ext.E
        if self.joint and self._joint_move(self.X, qst):
            return zeta, True
        if rej != "none" and self.G > 0.0:
            if rej == "table7.9":
                sig = self._sigma(self.X[:, :3], 3)
                z = self.ops.normals(self.draws, _flat(self.zbuf, self.N, 3))
                sig6 = np.concatenate([sig, np.zeros(3)])
                self.ops.roughen_compose(self.Q, self.W, z, sig6)
            else:
                sig = self._sigma(self.X[:, :3], 3)
                z = self.ops.normals(self.draws, _flat(self.zbuf, self.N, 3))
                self.ops.roughen_chart(self.X, z, sig, 3, qst, self.Q, self.W)
        if rej != "none":
            self._move_extras(k, 1.0 - rest)
        return zeta, True

    def _sigma(self, Xc, n):
        """Table 7.9 roughening σ of the cloud columns Xc (ranges, 𝒢, N, dimension n)."""
        return CP.roughening_sigma_nb(self.ops.ranges(Xc), self.G, self.N, n)

    def _move_extras(self, k, phi):
        if self.ext.n_moves:
            self.ext.move(k, phi, self.draws)
        else:
            self.ext.jitter(self.draws)

    def _resample_move(self, k, qref, qhat):
        """End-of-epoch resampling and rejuvenation (step 5)."""
        ext, cfg, N = self.ext, self.cfg, self.N
        self.dq_ok = False          # X2 (one of the exp(ζ) buffers) is overwritten below
        self._resample()
        self._reset_weights(k)
        if self.fixed:
            ext.take(self.idx)
            if cfg.rejuvenation == "table7.9":
                self._table79_extras()
            elif cfg.rejuvenation != "none":
                self._move_extras(k, 1.0)
            return
        if ext.ne:
            self.X[:, 6:] = ext.E
        self.ops.gather(self.X, self.idx, self.X2)     # [δp about qref, ω, e] of the new cloud
        ext.take(self.idx)
        if self.joint and self._joint_move(self.X2, qref):
            return
        rej = cfg.rejuvenation
        if rej == "table7.9":
            self._gather_qw()
            if ext.ne:
                self.X[:, 6:] = ext.E
            self.ops.chart(self.Q, self.W, np.ascontiguousarray(qhat), self.X)
            if self.G > 0.0:
                D = 6 + ext.ne
                sig = self._sigma(self.X, D)
                z = self.ops.normals(self.draws, _flat(self.ebuf, N, D))
                self.ops.roughen_compose(self.Q, self.W, z, np.ascontiguousarray(sig[:6]))
                if ext.ne:
                    ext.E = np.ascontiguousarray(ext.E + z[:, 6:] * sig[None, 6:])
            return
        if rej == "none" or not self.G > 0.0:
            self._gather_qw()
        else:
            sig = self._sigma(self.X2[:, :6], 6)
            z = self.ops.normals(self.draws, _flat(self.zbuf, N, 6))
            self.ops.roughen_chart(self.X2, z, sig, 6, qref, self.Q, self.W)
        if rej != "none":
            self._move_extras(k, 1.0)

    def _table79_extras(self):
        """Table 7.9 roughening of the extra states alone (attitude held at the truth)."""
        ext = self.ext
        if not (ext.ne and self.G > 0.0):
            return
        sig = self._sigma(ext.E, ext.ne)
        z = self.draws.normal(ext.E.shape)
        ext.E = np.ascontiguousarray(ext.E + z * sig[None, :])

    def _joint_move(self, X, qref):
        """The Liu–West kernel on the resampled chart rows X (N, 6 + ne) when the attitude
        cloud is compact (module docstring, step 5) → True when applied."""
        mean, C = self.ops.mean_cov(X)
        if not float(np.sqrt(max(0.0, np.max(np.diag(C)[:3])))) < self.spread:
            return False
        a, h = self.kern
        self.n_joint += 1
        if h == 0.0:
            self.ops.liu_west(X, self.ops.empty((self.N, 0)), np.zeros((X.shape[1], 0)), 1.0,
                              np.zeros(X.shape[1]), np.ascontiguousarray(qref), self.Q, self.W,
                              self.ext.E)
            return True
        L = _kernel_factor(C)
        eps = self.ops.normals(self.draws, _flat(self.ebuf, self.N, L.shape[1]))
        self.ops.liu_west(X, eps, np.ascontiguousarray(h * L), a, (1.0 - a) * mean,
                          np.ascontiguousarray(qref), self.Q, self.W, self.ext.E)
        return True

    def _estimate(self, w):
        """Posterior mean and covariance (step 4) → ``(q̂, ω̂, C, q_ref)``; leaves the chart
        ``[δp about q_ref, ω]`` of the cloud in ``self.X[:, :6]``."""
        ops, Q = self.ops, self.Q
        imax = int(ops.argmax(w))
        qmax = ops.row(Q, imax)
        if self.cfg.reference == "refined":
            qref = BK.grp_compose(np.ascontiguousarray(ops.grp_mean(Q, qmax, w)), qmax, GRP_A,
                                  GRP_F)
            qref = qref / np.linalg.norm(qref)
        else:
            qref = qmax
        qref = np.ascontiguousarray(qref)
        mean, C = ops.chart_stats(Q, self.W, w, qref, ops.row(self.W, imax), self.X)
        qhat = BK.grp_compose(np.ascontiguousarray(mean[:3]), qref, GRP_A, GRP_F)
        return qhat / np.linalg.norm(qhat), mean[3:6].copy(), 0.5 * (C + C.T), qref

    def _cloud(self, k):
        """Error rotation vectors (deg) of a weighted draw of ``cloud_size`` particles at
        epoch k (separate random stream: does not perturb the run)."""
        p, N = self.p, self.N
        crng = np.random.default_rng(np.random.SeedSequence([self.seed, 0xC10D, k]))
        sel = crng.choice(N, size=min(self.cloud_size, N), p=self.ops.to_host(self.w))
        tqk = np.broadcast_to(p.truth_q[k] / np.linalg.norm(p.truth_q[k]), (sel.size, 4))
        return np.degrees(rot.attitude_error_rotvec(tqk, self.ops.to_host(self.Q)[sel]))


_BACKENDS = {"numba": _NumbaOps, "numpy": _NumpyOps}


def _predict_any(backend, p, ext, k, Q, W, zeta, J, Ji, out):
    """Predicted magnitudes (N,) of the current cloud at epoch k without moving it (attitude
    only, + site bias, or with per-particle facet parameters)."""
    if ext.kind == "facets":
        return _predict_facets(backend, p, ext, k, Q, zeta, out)
    m = p.model
    if Q.shape[0] != out.shape[0]:       # attitude known, no per-particle state changes m(q)
        Q = np.ascontiguousarray(np.broadcast_to(Q, (out.shape[0], 4)))
        W = np.ascontiguousarray(np.broadcast_to(W, (out.shape[0], 3)))
    if backend == "numba":
        n_arr, a_arr, ids, prm = m._karrs
        BK.bpf_predict_nb(Q, W, 0.0, 0, J, Ji, 1, np.zeros((0, 6)), np.zeros((6, 6)), zeta,
                          m.s_eci[k], m.o_eci[k], n_arr, a_arr, ids, prm, float(m.offset[k]),
                          out, np.empty((0, 4)), 0, np.empty(0))
    else:
        Qm = Q
        if zeta.shape[0]:
            Qm = rot.quat_mult(rot.rotvec_to_quat(zeta), Q)
        out[:] = _predict_np(m, Qm, k)
    ext.add_bias(out, k)
    return out


def _kernel_factor(C):
    """L (D, r) with ``L Lᵀ = C`` for the joint kernel, formed in standardised coordinates
    (the components' scales differ by ~10⁴): Cholesky of the correlation matrix of the
    components with a spread, or its eigen-decomposition square root when singular; rows of
    components without spread are zero."""
    D = C.shape[0]
    sd = np.sqrt(np.clip(np.diag(C), 0.0, None))
    live = sd > 0.0
    L = np.zeros((D, 0))
    if np.any(live):
        Cl = C[np.ix_(live, live)] / np.outer(sd[live], sd[live])
        try:                 # Cholesky: ~20× cheaper than eigh for d = 30 on a busy machine
            Ll = sd[live][:, None] * np.linalg.cholesky(Cl)
        except np.linalg.LinAlgError:       # singular (e.g. a collapsed component)
            Ll = sd[live][:, None] * psd_sqrt(Cl)
        L = np.zeros((D, Ll.shape[1]))
        L[live] = Ll
    return L


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
