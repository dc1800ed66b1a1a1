"""Numba kernels of the bootstrap attitude particle filter (Bernard 2021 tables 7.7–7.11).

Particles are rows of ``Q`` (N,4) inertial→body quaternions (scalar first) and ``W`` (N,3) body
rates (rad/s). The attitude chart of a cloud about a reference ``q_ref`` is the GRP
(Bernard eq. 7.1, a = 1, f = 4) of ``δq_i = q_i ⊗ q_ref⁻¹`` with the sign ``δq1 ≥ 0``; a chart
buffer ``X`` (N, 6 + e) holds ``[δp_i, ω_i, extra states]`` per row.

Every kernel is parallel over particles (``prange``), allocation-free per particle, and its
result does not depend on the number of threads (reductions sum fixed chunks in order,
:func:`lightcurve.core.particles.n_chunks`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..core.particles import n_chunks
from ._kernels import _flux_pre, _normalize, _qmul_into, _rk4_one, _rotvec_q, flux_invariants

__all__ = ["bpf_predict_nb", "argmax_weights", "grp_weighted_mean", "chart_rows", "chart_stats",
           "roughen_chart", "roughen_compose", "liu_west_attitude", "min_abs_residual"]


@nb.njit(cache=True, inline="always")
def _grp_of(q, r, a, f, out):
    """GRP (3,) of ``q ⊗ r⁻¹`` with the sign of the scalar part made ≥ 0 (``r`` given as its
    conjugate's components: r = [r0, r1, r2, r3] of the reference, conjugated here)."""
    d0 = q[0] * r[0] + q[1] * r[1] + q[2] * r[2] + q[3] * r[3]
    d1 = -q[0] * r[1] + r[0] * q[1] - (-q[2] * r[3] + q[3] * r[2])
    d2 = -q[0] * r[2] + r[0] * q[2] - (-q[3] * r[1] + q[1] * r[3])
    d3 = -q[0] * r[3] + r[0] * q[3] - (-q[1] * r[2] + q[2] * r[1])
    if d0 < 0.0:
        d0 = -d0
        d1 = -d1
        d2 = -d2
        d3 = -d3
    den = a + d0
    out[0] = f * d1 / den
    out[1] = f * d2 / den
    out[2] = f * d3 / den


@nb.njit(cache=True, inline="always")
def _grp_quat(p0, p1, p2, a, f, d):
    """Quaternion ``d`` (4,) of the GRP (p0, p1, p2) (Bernard eq. 7.2–7.4)."""
    n2 = p0 * p0 + p1 * p1 + p2 * p2
    q0 = (-a * n2 + f * math.sqrt(f * f + (1.0 - a * a) * n2)) / (f * f + n2)
    cc = (a + q0) / f
    d[0] = q0
    d[1] = cc * p0
    d[2] = cc * p1
    d[3] = cc * p2


@nb.njit(cache=True, parallel=True)
def bpf_predict_nb(Q, W, dt, mode, J, Ji, nsub, noise, Lnoise, zeta, s, o, normals, areas, ids,
                   params, offset, m_out):
    """One fused bootstrap-PF prediction for every particle (in place on Q, W; fills m_out).

    mode 0: constant rate (controlled, exact ``q ← exp(ω dt) ⊗ q``), 1: torque-free RK4 with
    ``nsub`` sub-steps (uncontrolled). ``noise`` (N,r) standard normals and ``Lnoise`` (6,r) a
    square root of the process-noise covariance: the sample ``Lnoise · noise[i]`` =
    [δθ (rad), δω (rad/s)] is applied after the deterministic step (``noise`` (0,r): none).
    ``zeta`` (N,3) or (0,3): ACS attitude noise (rad) applied to the attitude *only for the
    predicted measurement* (controlled jitter model, Bernard eq. 7.8–7.11). ``m_out`` (N,)
    receives the predicted magnitudes (+inf: invisible; DESIGN.md magnitude equation). With
    ``s[0]`` NaN no magnitude is computed (propagation only). The facet sum uses the
    attitude-independent half vector and Fresnel factors of the epoch
    (:func:`~lightcurve.filters._kernels.flux_invariants`). The quaternions are renormalised.
    """
    N = Q.shape[0]
    h = dt / max(nsub, 1)
    use_noise = noise.shape[0] == N
    r = noise.shape[1]
    use_zeta = zeta.shape[0] == N
    predict = not np.isnan(s[0])
    Fr = np.zeros(normals.shape[0])
    hI = np.zeros(3)
    cI = -1.0
    if predict:
        hI, cI = flux_invariants(s, o, ids, params, Fr)
    nch = n_chunks(N)
    for c in nb.prange(nch):
        lo = c * N // nch
        hi = (c + 1) * N // nch
        nv = np.empty(6)
        q = np.empty(4)
        w = np.empty(3)
        dq = np.empty(4)
        qm = np.empty(4)
        sb = np.empty(3)
        ob = np.empty(3)
        hb = np.empty(3)
        k1q = np.empty(4)
        k2q = np.empty(4)
        k3q = np.empty(4)
        k4q = np.empty(4)
        k1w = np.empty(3)
        k2w = np.empty(3)
        k3w = np.empty(3)
        k4w = np.empty(3)
        qt = np.empty(4)
        wt = np.empty(3)
        for i in range(lo, hi):
            for j in range(4):
                q[j] = Q[i, j]
            for j in range(3):
                w[j] = W[i, j]
            if dt != 0.0:
                if mode == 0:
                    _rotvec_q(w[0] * dt, w[1] * dt, w[2] * dt, dq)
                    _qmul_into(dq, Q[i], q)
                else:
                    _rk4_one(q, w, J, Ji, h, nsub, k1q, k2q, k3q, k4q, k1w, k2w, k3w, k4w,
                             qt, wt)
            if use_noise:
                for j in range(6):
                    acc = 0.0
                    for cc in range(r):
                        acc += Lnoise[j, cc] * noise[i, cc]
                    nv[j] = acc
                _rotvec_q(nv[0], nv[1], nv[2], dq)
                for j in range(4):
                    qt[j] = q[j]
                _qmul_into(dq, qt, q)
                for j in range(3):
                    w[j] += nv[3 + j]
            _normalize(q)
            for j in range(4):
                Q[i, j] = q[j]
            for j in range(3):
                W[i, j] = w[j]
            if predict:
                if use_zeta:
                    _rotvec_q(zeta[i, 0], zeta[i, 1], zeta[i, 2], dq)
                    _qmul_into(dq, q, qm)
                else:
                    for j in range(4):
                        qm[j] = q[j]
                fl = _flux_pre(qm, s, o, hI, cI, Fr, normals, areas, ids, params, sb, ob, hb)
                m_out[i] = offset - 2.5 * math.log10(fl) if fl > 0.0 else np.inf


@nb.njit(cache=True, parallel=True)
def argmax_weights(w):
    """Index of the largest weight (the first one on ties, as ``numpy.argmax``)."""
    N = w.shape[0]
    nch = n_chunks(N)
    best = np.full(nch, -np.inf)
    arg = np.zeros(nch, dtype=np.int64)
    for c in nb.prange(nch):
        lo = c * N // nch
        hi = (c + 1) * N // nch
        b = -np.inf
        k = lo
        for i in range(lo, hi):
            if w[i] > b:
                b = w[i]
                k = i
        best[c] = b
        arg[c] = k
    b = -np.inf
    k = 0
    for c in range(nch):
        if best[c] > b:
            b = best[c]
            k = arg[c]
    return k


@nb.njit(cache=True, parallel=True)
def grp_weighted_mean(Q, qref, w, a, f):
    """``Σ_i w_i δp_i`` (3,) with δp_i the GRP of ``Q_i ⊗ qref⁻¹`` (Bernard eq. 7.100–7.102)."""
    N = Q.shape[0]
    nch = n_chunks(N)
    part = np.zeros((nch, 3))
    for c in nb.prange(nch):
        lo = c * N // nch
        hi = (c + 1) * N // nch
        g = np.empty(3)
        for i in range(lo, hi):
            _grp_of(Q[i], qref, a, f, g)
            wi = w[i]
            for j in range(3):
                part[c, j] += wi * g[j]
    out = np.zeros(3)
    for c in range(nch):
        for j in range(3):
            out[j] += part[c, j]
    return out


@nb.njit(cache=True, parallel=True)
def chart_rows(Q, W, qref, a, f, X):
    """``X[i, :3]`` = GRP of ``Q_i ⊗ qref⁻¹``, ``X[i, 3:6] = W_i`` (the chart of eq. 7.101)."""
    N = Q.shape[0]
    for i in nb.prange(N):
        _grp_of(Q[i], qref, a, f, X[i, :3])
        for j in range(3):
            X[i, 3 + j] = W[i, j]


@nb.njit(cache=True, parallel=True)
def chart_stats(Q, W, w, qref, a, f, w0, X):
    """:func:`chart_rows` fused with the weighted moments of the rows ``x_i = [δp_i, ω_i]``:
    returns ``(mean (6,), cov (6,6))`` with ``mean = Σ w x``, ``cov = Σ w (x − mean)(x −
    mean)ᵀ`` (Bernard eq. 7.102–7.104; normalised weights). One pass, accumulated about the
    shift ``[0, 0, 0, w0]`` (w0 a rate near the mean, e.g. the heaviest particle's) so that
    the one-pass covariance keeps full precision."""
    N = Q.shape[0]
    nch = n_chunks(N)
    S1 = np.zeros((nch, 6))
    S2 = np.zeros((nch, 6, 6))
    for c in nb.prange(nch):
        lo = c * N // nch
        hi = (c + 1) * N // nch
        x = np.empty(6)
        for i in range(lo, hi):
            _grp_of(Q[i], qref, a, f, X[i, :3])
            for j in range(3):
                X[i, 3 + j] = W[i, j]
                x[j] = X[i, j]
                x[3 + j] = W[i, j] - w0[j]
            wi = w[i]
            for d in range(6):
                xd = wi * x[d]
                S1[c, d] += xd
                for e in range(d + 1):
                    S2[c, d, e] += xd * x[e]
    m = np.zeros(6)
    C = np.zeros((6, 6))
    for c in range(nch):
        for d in range(6):
            m[d] += S1[c, d]
            for e in range(d + 1):
                C[d, e] += S2[c, d, e]
    for d in range(6):
        for e in range(d + 1):
            C[d, e] -= m[d] * m[e]
            C[e, d] = C[d, e]
    for j in range(3):
        m[3 + j] += w0[j]
    return m, C


@nb.njit(cache=True, parallel=True)
def roughen_chart(X, z, sig, ncols, qref, a, f, Q, W):
    """Roughening in the chart about ``qref``: ``x_i[:ncols] += σ ⊙ z_i`` for the rows
    ``x_i = [δp, ω]`` of X (first 6 columns), then ``Q_i = grp2q(δp_i) ⊗ qref``, ``W_i = ω_i``
    (ncols = 3: the attitude only, W left as it is). z (N, ncols) standard normals."""
    N = Q.shape[0]
    for i in nb.prange(N):
        p0 = X[i, 0] + sig[0] * z[i, 0]
        p1 = X[i, 1] + sig[1] * z[i, 1]
        p2 = X[i, 2] + sig[2] * z[i, 2]
        d = np.empty(4)
        _grp_quat(p0, p1, p2, a, f, d)
        _qmul_into(d, qref, Q[i])
        _normalize(Q[i])
        if ncols == 6:
            for j in range(3):
                W[i, j] = X[i, 3 + j] + sig[3 + j] * z[i, 3 + j]


@nb.njit(cache=True, parallel=True)
def roughen_compose(Q, W, z, sig, a, f):
    """Bernard table 7.9 "Update state": ``c_i = σ ⊙ z_i``, ``q_i ← q(c_θ,i) ⊗ q_i`` (c_θ a GRP,
    eq. 7.108) and ``ω_i ← ω_i + c_ω,i`` (eq. 7.109); z (N,6) standard normals."""
    N = Q.shape[0]
    for i in nb.prange(N):
        d = np.empty(4)
        qi = np.empty(4)
        _grp_quat(sig[0] * z[i, 0], sig[1] * z[i, 1], sig[2] * z[i, 2], a, f, d)
        for j in range(4):
            qi[j] = Q[i, j]
        _qmul_into(d, qi, Q[i])
        _normalize(Q[i])
        for j in range(3):
            W[i, j] += sig[3 + j] * z[i, 3 + j]


@nb.njit(cache=True, parallel=True)
def liu_west_attitude(X, eps, M, sa, c, qref, a, f, Q, W, E):
    """Liu & West (2001) kernel on the chart rows ``x_i = [δp, ω, e]`` of X (N, 6 + ne):
    ``x_i ← sa · x_i + c + M eps_i`` (``c = (1 − sa) x̄``, ``M = h L``), then
    ``Q_i = grp2q(δp_i) ⊗ qref``, ``W_i = ω_i``, ``E_i = e_i`` (E (N, ne))."""
    N = Q.shape[0]
    D = M.shape[0]
    r = eps.shape[1]
    for i in nb.prange(N):
        x = np.empty(D)
        for d in range(D):
            acc = sa * X[i, d] + c[d]
            for j in range(r):
                acc += M[d, j] * eps[i, j]
            x[d] = acc
        dq = np.empty(4)
        _grp_quat(x[0], x[1], x[2], a, f, dq)
        _qmul_into(dq, qref, Q[i])
        _normalize(Q[i])
        for j in range(3):
            W[i, j] = x[3 + j]
        for d in range(6, D):
            E[i, d - 6] = x[d]


@nb.njit(cache=True, parallel=True)
def min_abs_residual(mpred, y):
    """``min_i |y − m_i|`` over the finite predictions (+inf when none is finite)."""
    N = mpred.shape[0]
    nch = n_chunks(N)
    part = np.full(nch, np.inf)
    for c in nb.prange(nch):
        lo = c * N // nch
        hi = (c + 1) * N // nch
        b = np.inf
        for i in range(lo, hi):
            m = mpred[i]
            if np.isfinite(m):
                v = abs(y - m)
                if v < b:
                    b = v
        part[c] = b
    b = np.inf
    for c in range(nch):
        if part[c] < b:
            b = part[c]
    return b
