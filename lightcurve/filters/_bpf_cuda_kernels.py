"""CUDA kernels of the GPU particle filter (:mod:`lightcurve.filters.bpf_gpu`); imported only
when that backend runs (needs numba-cuda). Module-level kernels, so numba's CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``) can run them.

Reductions: each block of :data:`TPB` threads accumulates a grid-stride share of the particles
in registers, sums (or takes the extremum of) its rows in shared memory and writes one row of
block partials (:func:`_block_reduce`); the host combines the partials in block order.
"""

from __future__ import annotations

import math

import numpy as np
from numba import cuda

from ..core import particles as CP
from . import _bpf_kernels as BK

from numba.core import config as _config

TPB = 32 if _config.ENABLE_CUDASIM else 128
"""Threads per block (32 in the simulator, where every thread is a Python thread)."""

def _dev(f):
    """The njit function ``f`` as called from a kernel: itself on a device (numba-cuda compiles
    it for the GPU); in the CUDA simulator a wrapper that hands it the NumPy arrays behind the
    simulator's fake device arrays (the compiled CPU function cannot take those)."""
    if not _config.ENABLE_CUDASIM:
        return f

    def call(*args):
        return f(*[getattr(a, "_ary", a) for a in args])

    return call


predict_row = _dev(BK.predict_row)
roughen_chart_row = _dev(BK.roughen_chart_row)
roughen_compose_row = _dev(BK.roughen_compose_row)
liu_west_row = _dev(BK.liu_west_row)
grp_of = _dev(BK._grp_of)
chart_row = _dev(BK.chart_row)
chart_moment_row = _dev(BK.chart_moment_row)
ziggurat_normal = _dev(CP.ziggurat_normal)
first_above = _dev(CP._first_above)


@cuda.jit(device=True)
def _block_reduce(sh, t, K, sign, part):
    """Reduce the rows of the shared array ``sh`` (TPB, K), once every thread of the block has
    written its row ``t``, into ``sh[0]`` — their sums (``sign = 0``), maxima (``+1``) or
    minima (``−1``) — and store that as the block's row ``part[block, :K]``."""
    cuda.syncthreads()
    step = TPB // 2
    while step > 0:
        if t < step:
            for k in range(K):
                if sign == 0.0:
                    sh[t, k] += sh[t + step, k]
                elif sign * sh[t + step, k] > sign * sh[t, k]:
                    sh[t, k] = sh[t + step, k]
        cuda.syncthreads()
        step //= 2
    if t == 0:
        for k in range(K):
            part[cuda.blockIdx.x, k] = sh[0, k]

@cuda.jit
def k_predict(Q, W, dt, mode, h, nsub, Jt, Kt, noise, Lnoise, use_noise, zeta, use_zeta,
              predict, s, o, hI, cI, Fr, normals, areas, ids, params, offset, m_out):
    i = cuda.grid(1)
    if i < Q.shape[0]:
        predict_row(i, Q, W, dt, mode, h, nsub, Jt, Kt, noise, Lnoise, use_noise, zeta,
                       use_zeta, predict, s, o, hI, cI, Fr, normals, areas, ids, params,
                       offset, m_out)

@cuda.jit
def k_normals(k0, k1, cl, ch, zx, zr, out):
    i = cuda.grid(1)
    if i < out.shape[0]:
        for j in range(out.shape[1]):
            out[i, j] = ziggurat_normal(np.uint64(i), np.uint64(j), cl, ch, k0, k1,
                                           zx, zr)

@cuda.jit
def k_fill(a, v):
    i = cuda.grid(1)
    if i < a.shape[0]:
        a[i] = v

@cuda.jit
def k_chart(Q, W, qref, a, f, X):
    i = cuda.grid(1)
    if i < Q.shape[0]:
        chart_row(i, Q, W, qref, a, f, X)

@cuda.jit
def k_scale2(a, v):
    i = cuda.grid(1)
    if i < a.shape[0]:
        for j in range(a.shape[1]):
            a[i, j] *= v

@cuda.jit
def k_gather(src, idx, dst):
    i = cuda.grid(1)
    if i < dst.shape[0]:
        for j in range(src.shape[1]):
            dst[i, j] = src[idx[i], j]

@cuda.jit
def k_add(logw, ll, phi):
    i = cuda.grid(1)
    if i < logw.shape[0]:
        logw[i] += phi * ll[i]

@cuda.jit
def k_max(a, b, phi, part):
    """Block maxima of ``a + φ b`` (φ = 0: of a)."""
    sh = cuda.shared.array((TPB, 1), np.float64)
    t = cuda.threadIdx.x
    m = -math.inf
    i = cuda.grid(1)
    while i < a.shape[0]:
        v = a[i] + phi * b[i] if phi != 0.0 else a[i]
        if v > m:
            m = v
        i += cuda.gridsize(1)
    sh[t, 0] = m
    _block_reduce(sh, t, 1, 1.0, part)

@cuda.jit
def k_sumexp(logw, ll, phi, m, part):
    sh = cuda.shared.array((TPB, 2), np.float64)
    t = cuda.threadIdx.x
    s1 = 0.0
    s2 = 0.0
    i = cuda.grid(1)
    while i < logw.shape[0]:
        a = logw[i] + phi * ll[i] if phi != 0.0 else logw[i]
        if a > -math.inf:
            e = math.exp(a - m)
            s1 += e
            s2 += e * e
        i += cuda.gridsize(1)
    sh[t, 0] = s1
    sh[t, 1] = s2
    _block_reduce(sh, t, 2, 0.0, part)

@cuda.jit
def k_expw(logw, mx, w, part):
    sh = cuda.shared.array((TPB, 1), np.float64)
    t = cuda.threadIdx.x
    s = 0.0
    i = cuda.grid(1)
    while i < logw.shape[0]:
        e = math.exp(logw[i] - mx)
        w[i] = e
        s += e
        i += cuda.gridsize(1)
    sh[t, 0] = s
    _block_reduce(sh, t, 1, 0.0, part)

@cuda.jit
def k_normw(logw, w, lse, s, part):
    sh = cuda.shared.array((TPB, 1), np.float64)
    t = cuda.threadIdx.x
    s2 = 0.0
    i = cuda.grid(1)
    while i < logw.shape[0]:
        logw[i] -= lse
        w[i] /= s
        s2 += w[i] * w[i]
        i += cuda.gridsize(1)
    sh[t, 0] = s2
    _block_reduce(sh, t, 1, 0.0, part)

@cuda.jit
def k_innov(logw, mpred, y, sig, ll, mx, mean, second, part):
    """Pass 1 (second = False): ll and Σe, Σe·m; pass 2: Σe (m − mean)²."""
    sh = cuda.shared.array((TPB, 2), np.float64)
    t = cuda.threadIdx.x
    s0 = 0.0
    s1 = 0.0
    i = cuda.grid(1)
    while i < logw.shape[0]:
        m = mpred[i]
        fin = not (math.isinf(m) or math.isnan(m))
        if fin:
            e = math.exp(logw[i] - mx) if mx > -math.inf else 1.0
            if second:
                s0 += e * (m - mean) * (m - mean)
            else:
                s0 += e
                s1 += e * m
                r = (y - m) / sig
                ll[i] = -0.5 * r * r
        elif not second:
            ll[i] = -math.inf
        i += cuda.gridsize(1)
    sh[t, 0] = s0
    sh[t, 1] = s1
    _block_reduce(sh, t, 2, 0.0, part)

@cuda.jit
def k_nearest(mpred, y, part):
    sh = cuda.shared.array((TPB, 1), np.float64)
    t = cuda.threadIdx.x
    b = math.inf
    i = cuda.grid(1)
    while i < mpred.shape[0]:
        m = mpred[i]
        if not (math.isinf(m) or math.isnan(m)):
            v = abs(y - m)
            if v < b:
                b = v
        i += cuda.gridsize(1)
    sh[t, 0] = b
    _block_reduce(sh, t, 1, -1.0, part)

@cuda.jit
def k_first_equal(w, v, part):
    """Block minima of the indices i with w[i] == v (N where none)."""
    sh = cuda.shared.array((TPB, 1), np.float64)
    t = cuda.threadIdx.x
    b = float(w.shape[0])
    i = cuda.grid(1)
    while i < w.shape[0]:
        if w[i] == v and i < b:
            b = float(i)
        i += cuda.gridsize(1)
    sh[t, 0] = b
    _block_reduce(sh, t, 1, -1.0, part)

@cuda.jit
def k_grp_mean(Q, qref, w, a, f, part):
    sh = cuda.shared.array((TPB, 3), np.float64)
    g = cuda.local.array(3, np.float64)
    t = cuda.threadIdx.x
    for k in range(3):
        sh[t, k] = 0.0
    i = cuda.grid(1)
    while i < Q.shape[0]:
        grp_of(Q[i], qref, a, f, g)
        for k in range(3):
            sh[t, k] += w[i] * g[k]
        i += cuda.gridsize(1)
    _block_reduce(sh, t, 3, 0.0, part)

@cuda.jit
def k_chart_stats(Q, W, w, qref, a, f, w0, X, part):
    """X rows = [δp, ω]; block sums of w x and w x xᵀ (x about [0, w0], lower triangle)."""
    sh = cuda.shared.array((TPB, 27), np.float64)
    x = cuda.local.array(6, np.float64)
    t = cuda.threadIdx.x
    for k in range(27):
        sh[t, k] = 0.0
    i = cuda.grid(1)
    while i < Q.shape[0]:
        chart_moment_row(i, Q, W, qref, a, f, w0, X, x)
        wi = w[i]
        kk = 6
        for d in range(6):
            sh[t, d] += wi * x[d]
            for e in range(d + 1):
                sh[t, kk] += wi * x[d] * x[e]
                kk += 1
        i += cuda.gridsize(1)
    _block_reduce(sh, t, 27, 0.0, part)

@cuda.jit
def k_colsum(X, mean, second, part):
    """Block column sums of X (second = False) or of the lower-triangle products of X − mean
    (True); at most 6 columns (attitude and rate)."""
    sh = cuda.shared.array((TPB, 21), np.float64)
    t = cuda.threadIdx.x
    D = X.shape[1]
    for k in range(21):
        sh[t, k] = 0.0
    i = cuda.grid(1)
    while i < X.shape[0]:
        if second:
            kk = 0
            for d in range(D):
                for e in range(d + 1):
                    sh[t, kk] += (X[i, d] - mean[d]) * (X[i, e] - mean[e])
                    kk += 1
        else:
            for d in range(D):
                sh[t, d] += X[i, d]
        i += cuda.gridsize(1)
    _block_reduce(sh, t, 21, 0.0, part)

@cuda.jit
def k_ranges(X, part):
    """Block minima (columns 0…D−1) and maxima (D…2D−1, stored negated) of X's columns."""
    sh = cuda.shared.array((TPB, 12), np.float64)
    t = cuda.threadIdx.x
    D = X.shape[1]
    for k in range(12):
        sh[t, k] = math.inf
    i = cuda.grid(1)
    while i < X.shape[0]:
        for d in range(D):
            v = X[i, d]
            if v < sh[t, d]:
                sh[t, d] = v
            if -v < sh[t, 6 + d]:
                sh[t, 6 + d] = -v
        i += cuda.gridsize(1)
    _block_reduce(sh, t, 12, -1.0, part)

@cuda.jit
def k_scan(w, C, part):
    """Inclusive scan of w within each block of TPB (serial in thread 0 of the block, in
    order) and the block totals; block offsets are added by k_offsets."""
    b = cuda.blockIdx.x
    if cuda.threadIdx.x == 0:
        lo = b * TPB
        hi = min(lo + TPB, w.shape[0])
        c = 0.0
        last = -1.0
        for i in range(lo, hi):
            c += w[i]
            C[i] = c
            if w[i] > 0.0:
                last = float(i)
        part[b, 0] = c
        part[b, 1] = last

@cuda.jit
def k_offsets(C, off):
    i = cuda.grid(1)
    if i < C.shape[0]:
        C[i] += off[i // TPB]

@cuda.jit
def k_search(C, total, last, u0, u, systematic, idx):
    """idx[j] = smallest i with position_j < C_i (capped at last); position
    (u0 + j)/n·total (systematic) or u[j]·total."""
    j = cuda.grid(1)
    n = idx.shape[0]
    if j < n:
        p = (u0 + j) / n * total if systematic else u[j] * total
        idx[j] = first_above(C, last, p)

@cuda.jit
def k_roughen_chart(X, z, sig, ncols, qref, a, f, Q, W):
    i = cuda.grid(1)
    if i < Q.shape[0]:
        roughen_chart_row(i, X, z, sig, ncols, qref, a, f, Q, W)

@cuda.jit
def k_roughen_compose(Q, W, z, sig, a, f):
    i = cuda.grid(1)
    if i < Q.shape[0]:
        roughen_compose_row(i, Q, W, z, sig, a, f)

@cuda.jit
def k_liu_west(X, eps, M, sa, c, qref, a, f, Q, W, E):
    i = cuda.grid(1)
    if i < Q.shape[0]:
        liu_west_row(i, X, eps, M, sa, c, qref, a, f, Q, W, E)
