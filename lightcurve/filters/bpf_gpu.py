"""CUDA backend of the bootstrap particle filter (numba-cuda; the optional ``gpu`` extra).

The filter is the one of :mod:`lightcurve.filters.bpf` — the same driver, configuration
(:class:`~lightcurve.filters.bpf.BPFConfig`, both variants) and random numbers — with its
per-particle stages as CUDA kernels on device arrays: prediction (the per-particle function
:func:`~lightcurve.filters._bpf_kernels.predict_row` that the CPU kernel runs: the core's
rotation algebra, RK4 step and Cook–Torrance), the counter-based normals (the same
Philox4x32-10 ziggurat draws as the CPU, :func:`~lightcurve.core.particles.ziggurat_normal`),
log weights, N_eff and tempering, resampling (cumulative weights by a block scan, then a binary
search per output), gathers, the moves (table 7.9 roughening, the chart roughening and the
Liu–West kernel, :mod:`lightcurve.filters._bpf_kernels` row functions), and the reductions of
the estimate. Reductions run per block in shared memory and the block partials are summed on
the host in block order, so a run is deterministic for a given seed and N. Only small
per-epoch values (moments, the 6×6 kernel factor, one uniform) cross to the host.

Without numba-cuda or a CUDA device :func:`run_bpf_gpu` raises a clear error; the package
imports without it. Under ``NUMBA_ENABLE_CUDASIM=1`` the same kernels run in numba's CUDA
simulator (no GPU, slow: tests use a few hundred particles).

Not on the GPU (NotImplementedError): extra states (site biases, Model 3), attitude held at
the truth, ``rng="numpy"``.
"""

from __future__ import annotations

import math

import numpy as np

from ..core import particles as CP
from ..core.dynamics import mat9
from . import _bpf_kernels as BK
from . import bpf as B

__all__ = ["run_bpf_gpu", "gpu_available"]

_K = {}             # compiled kernels (built on first use)


def gpu_available() -> tuple[bool, str]:
    """``(True, "")`` when numba-cuda imports and sees a CUDA device (or its simulator), else
    ``(False, reason)``."""
    try:
        from numba import cuda
    except ImportError as exc:        # pragma: no cover - depends on the environment
        return False, f"numba-cuda is not installed ({exc}); pip install 'lightcurve[gpu]'"
    try:
        ok = cuda.is_available()
    except Exception as exc:  # noqa: BLE001 - the driver's own error text is the reason
        return False, f"no usable CUDA device: {exc}"
    return (True, "") if ok else (False, "no CUDA device found (numba.cuda.is_available())")


def _kernels():
    """The compiled CUDA kernels (:mod:`lightcurve.filters._bpf_cuda_kernels`, imported on first
    use), as a dict name → kernel."""
    global _TPB
    if not _K:
        from . import _bpf_cuda_kernels as CK

        _K.update({k: getattr(CK, k) for k in dir(CK) if k.startswith("k_")})
        _TPB = CK.TPB
    return _K


_TPB = 128          # threads per block (set from _bpf_cuda_kernels.TPB on first use)


class _CudaOps:
    """The stages of :class:`lightcurve.filters.bpf._Run` on device arrays (module docstring)."""

    def __init__(self):
        from numba import cuda

        self.cuda = cuda
        self.k = _kernels()
        self.zx = cuda.to_device(CP._ZIG_X)
        self.zr = cuda.to_device(CP._ZIG_R)

    # ---- arrays -------------------------------------------------------------------
    def _grid(self, n, cap=None):
        b = max(1, (int(n) + _TPB - 1) // _TPB)
        return min(b, cap) if cap else b

    def empty(self, shape, dtype=np.float64):
        if np.prod(shape) == 0:
            return self.cuda.to_device(np.empty(shape, dtype=dtype))
        return self.cuda.device_array(shape, dtype=dtype)

    def full(self, shape, value):
        return self.cuda.to_device(np.full(shape, float(value)))

    def from_host(self, a):
        return self.cuda.to_device(np.ascontiguousarray(a, dtype=np.float64))

    def to_host(self, a):
        return a.copy_to_host() if hasattr(a, "copy_to_host") else a

    def fill(self, a, value):
        if a.size:
            self.k["k_fill"][self._grid(a.size), _TPB](a, float(value))

    def row(self, a, i):
        return a[i:i + 1].copy_to_host()[0]

    def scale(self, a, f):
        self.k["k_scale2"][self._grid(a.shape[0]), _TPB](a, float(f))

    def normals(self, draws, out):
        if out.size == 0:
            return out
        c = int(draws.call)
        self.k["k_normals"][self._grid(out.shape[0]), _TPB](
            np.uint64(draws.k0), np.uint64(draws.k1), np.uint64(c & 0xFFFFFFFF),
            np.uint64(c >> 32), self.zx, self.zr, out)
        draws.call += 1
        return out

    def gather(self, src, idx, dst):
        self.k["k_gather"][self._grid(dst.shape[0]), _TPB](src, idx, dst)

    # ---- reductions ---------------------------------------------------------------
    def _partials(self, kern, n, K, *args):
        g = self._grid(n, 1024)
        part = self.cuda.device_array((g, K))
        kern[g, _TPB](*args, part)
        return part.copy_to_host()

    def _max(self, a, b, phi):
        return float(np.max(self._partials(self.k["k_max"], a.shape[0], 1, a, b, phi)))

    def _sumexp(self, logw, ll, phi, m):
        p = self._partials(self.k["k_sumexp"], logw.shape[0], 2, logw, ll, phi, m)
        return float(np.sum(p[:, 0])), float(np.sum(p[:, 1]))

    def innov(self, logw, mpred, y, sig, ll):
        mx = self._max(logw, logw, 0.0)
        p = self._partials(self.k["k_innov"], logw.shape[0], 2, logw, mpred, y, sig, ll, mx,
                           0.0, False)
        s0, s1 = float(np.sum(p[:, 0])), float(np.sum(p[:, 1]))
        if not s0 > 0.0:
            return np.nan, np.nan, False
        mean = s1 / s0
        p = self._partials(self.k["k_innov"], logw.shape[0], 2, logw, mpred, y, sig, ll, mx,
                           mean, True)
        return mean, float(np.sum(p[:, 0])) / s0, True

    def loglik(self, logw, mpred, y, sig, ll):
        self.innov(logw, mpred, y, sig, ll)

    def nearest(self, mpred, y):
        return float(np.min(self._partials(self.k["k_nearest"], mpred.shape[0], 1, mpred,
                                           float(y))))

    def addnorm(self, logw, ll, phi, w):
        N = logw.shape[0]
        if phi != 0.0:
            self.k["k_add"][self._grid(N), _TPB](logw, ll, phi)
        mx = self._max(logw, logw, 0.0)
        if not mx > -np.inf:
            return 0.0, False
        s = float(np.sum(self._partials(self.k["k_expw"], N, 1, logw, mx, w)))
        lse = mx + math.log(s)
        s2 = float(np.sum(self._partials(self.k["k_normw"], N, 1, logw, w, lse, s)))
        return 1.0 / s2, True

    def ess(self, logw, ll, phi):
        m = self._max(logw, ll, phi)
        if m == -np.inf or np.isnan(m):
            return 0.0
        s1, s2 = self._sumexp(logw, ll, phi, m)
        return s1 * s1 / s2

    def temper(self, logw, ll, rest, target, steps):
        """:func:`lightcurve.core.particles.temper_exponent` with device reductions."""
        mw = self._max(logw, logw, 0.0)
        ml = self._max(ll, ll, 0.0)
        lo, hi = 0.0, rest
        for _ in range(steps):
            mid = 0.5 * (lo + hi)
            e = 0.0
            if mw > -np.inf and ml > -np.inf:
                s1, s2 = self._sumexp(logw, ll, mid, mw + mid * ml)
                e = s1 * s1 / s2 if (s1 > 1e-150 and s2 > 0.0) else self.ess(logw, ll, mid)
            if e >= target:
                lo = mid
            else:
                hi = mid
        return lo

    def argmax(self, w):
        mx = self._max(w, w, 0.0)
        return int(np.min(self._partials(self.k["k_first_equal"], w.shape[0], 1, w, mx)))

    def grp_mean(self, Q, qref, w):
        p = self._partials(self.k["k_grp_mean"], Q.shape[0], 3, Q,
                           self.cuda.to_device(np.ascontiguousarray(qref)), w, B.GRP_A, B.GRP_F)
        return p.sum(axis=0)

    def chart(self, Q, W, qref, X):
        self.k["k_chart"][self._grid(Q.shape[0]), _TPB](
            Q, W, self.cuda.to_device(np.ascontiguousarray(qref)), B.GRP_A, B.GRP_F, X)

    def chart_stats(self, Q, W, w, qref, w0, X):
        p = self._partials(self.k["k_chart_stats"], Q.shape[0], 27, Q, W, w,
                           self.cuda.to_device(np.ascontiguousarray(qref)), B.GRP_A, B.GRP_F,
                           self.cuda.to_device(np.ascontiguousarray(w0)), X).sum(axis=0)
        m = p[:6].copy()
        C = np.zeros((6, 6))
        kk = 6
        for d in range(6):
            for e in range(d + 1):
                C[d, e] = C[e, d] = p[kk] - m[d] * m[e]
                kk += 1
        m[3:] += w0
        return m, C

    def mean_cov(self, X):
        N, D = X.shape
        if D > 6:
            raise NotImplementedError("the GPU backend has no extra states (D ≤ 6)")
        mean = self._partials(self.k["k_colsum"], N, 21, X, self.cuda.to_device(np.zeros(6)),
                              False).sum(axis=0)[:D] / N
        p = self._partials(self.k["k_colsum"], N, 21, X, self.cuda.to_device(mean),
                           True).sum(axis=0)
        C = np.zeros((D, D))
        kk = 0
        for d in range(D):
            for e in range(d + 1):
                C[d, e] = C[e, d] = p[kk] / N
                kk += 1
        return mean, C

    def ranges(self, Xc):
        D = Xc.shape[1]
        p = self._partials(self.k["k_ranges"], Xc.shape[0], 12, Xc)
        return -p[:, 6:6 + D].min(axis=0) - p[:, :D].min(axis=0)

    # ---- resampling -----------------------------------------------------------------
    def _cumulative(self, w, C):
        N = w.shape[0]
        nb_ = (N + _TPB - 1) // _TPB
        part = self.cuda.device_array((nb_, 2))
        self.k["k_scan"][nb_, _TPB](w, C, part)
        p = part.copy_to_host()
        off = np.concatenate([[0.0], np.cumsum(p[:-1, 0])])
        self.k["k_offsets"][self._grid(N), _TPB](C, self.cuda.to_device(off))
        total = float(off[-1] + p[-1, 0])
        last = int(np.max(p[:, 1]))
        return total, last

    def systematic(self, w, u0, C, idx):
        total, last = self._cumulative(w, C)
        if last < 0:
            return False
        self.k["k_search"][self._grid(idx.shape[0]), _TPB](C, total, last, float(u0), C, True,
                                                           idx)
        return True

    def sorted_merge(self, w, u, C, idx):
        total, last = self._cumulative(w, C)
        if last < 0:
            return False
        self.k["k_search"][self._grid(idx.shape[0]), _TPB](C, total, last, 0.0,
                                                           self.cuda.to_device(u), False, idx)
        return True

    # ---- moves ------------------------------------------------------------------------
    def roughen_chart(self, X, z, sig, ncols, qref, Q, W):
        self.k["k_roughen_chart"][self._grid(Q.shape[0]), _TPB](
            X, z, self.cuda.to_device(sig), ncols, self.cuda.to_device(qref), B.GRP_A, B.GRP_F,
            Q, W)

    def roughen_compose(self, Q, W, z, sig):
        self.k["k_roughen_compose"][self._grid(Q.shape[0]), _TPB](
            Q, W, z, self.cuda.to_device(np.ascontiguousarray(sig)), B.GRP_A, B.GRP_F)

    def liu_west(self, X, eps, M, sa, c, qref, Q, W, E):
        Ed = self.cuda.to_device(np.zeros((Q.shape[0], 0))) if not hasattr(E, "copy_to_host") \
            else E
        self.k["k_liu_west"][self._grid(Q.shape[0]), _TPB](
            X, eps, self.cuda.to_device(np.ascontiguousarray(M)), float(sa),
            self.cuda.to_device(np.ascontiguousarray(c)), self.cuda.to_device(qref), B.GRP_A,
            B.GRP_F, Q, W, Ed)

    # ---- prediction ---------------------------------------------------------------------
    def predict(self, run, k, dt, z, L, zeta, s):
        m = run.p.model
        n_arr, a_arr, ids, prm = (self.cuda.to_device(np.ascontiguousarray(x))
                                  for x in m._karrs)
        predict = not np.isnan(s[0])
        Fr = np.zeros(n_arr.shape[0])
        hI, cI = (0.0, 0.0, 0.0), -1.0
        if predict:
            hI, cI = BK.flux_invariants(s, m.o_eci[k], m._karrs[2], m._karrs[3], Fr)
        nsub = run.p.dynamics.nsub(dt) if (run.mode and dt != 0.0) else 1
        N = run.Q.shape[0]
        zd = z if hasattr(z, "copy_to_host") else self.cuda.to_device(np.zeros((0, 6)))
        zeta_d = zeta if hasattr(zeta, "copy_to_host") else self.cuda.to_device(np.zeros((0, 3)))
        self.k["k_predict"][self._grid(N), _TPB](
            run.Q, run.W, float(dt), int(run.mode), dt / max(nsub, 1), int(nsub),
            mat9(run.J), mat9(run.Ji), zd, self.cuda.to_device(np.ascontiguousarray(L)),
            zd.shape[0] == N, zeta_d, zeta_d.shape[0] == N, predict,
            self.cuda.to_device(np.ascontiguousarray(s)),
            self.cuda.to_device(np.ascontiguousarray(m.o_eci[k])), tuple(float(x) for x in hI),
            float(cI), self.cuda.to_device(Fr), n_arr, a_arr, ids, prm, float(m.offset[k]),
            run.mpred)


def run_bpf_gpu(problem, config=None, *, seed=0, bias=None, facets=None, attitude="estimate",
                initial_cloud=None, **overrides):
    """:func:`lightcurve.filters.bpf.run_bpf` with the CUDA backend (module docstring) →
    Estimate. Same arguments; ``est.meta["bpf"]["backend"] == "cuda"``."""
    from ..errors import InputError

    ok, why = gpu_available()
    if not ok:
        raise InputError(f"--device gpu: {why}", field="device", value="gpu")
    cfg = B._config(config, overrides)
    if bias is not None or facets is not None or attitude != "estimate" or \
            getattr(problem, "attitude_known", False):
        raise NotImplementedError("the GPU particle filter estimates attitude and rate only: "
                                  "reflection states and the attitude-known mode run on the "
                                  "CPU (device='cpu')")
    if cfg.rng != "philox":
        raise NotImplementedError("the GPU particle filter draws counter-based normals only "
                                  "(rng='philox')")
    if not problem.model.kernel_ok:
        raise NotImplementedError("the shape has BRDFs without a kernel; use device='cpu'")
    B._BACKENDS.setdefault("cuda", _CudaOps)
    run = B._Run(problem, cfg, seed, "cuda", None, None, attitude, cfg.keep_clouds,
                 cfg.cloud_size, initial_cloud)
    return run.run()
