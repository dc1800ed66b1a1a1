"""Numba kernels of the attitude filters (plain float64 arrays; no validation).

Conventions: quaternions scalar first, inertial→body passive (``v_b = A(q) v_I``); body rates
ω in body axes, rad/s; the attitude *error* of a state ``q`` relative to a reference ``q_ref``
is ``δq = q ⊗ q_ref⁻¹`` (so ``q = δq ⊗ q_ref``), expressed as a GRP ``p = f δq_v/(a + δq1)``
(Bernard eq. 3.28, default a = 1, f = 4) with the sign of ``δq`` chosen so that ``δq1 ≥ 0``,
or as a rotation vector (small-angle error, ``δq = [cos(|θ|/2), θ̂ sin(|θ|/2)]``).

Every ``prange`` loop is over independent particles / sigma points, so the results do not
depend on the number of threads (only the heavy kernels — magnitudes, RK4, the fused BPF
prediction — are compiled parallel; the cheap chart maps run serially, because waking a
thread pool costs more than they do); random numbers are drawn by the caller from a
``numpy.random.Generator`` and passed in, which keeps runs reproducible bit for bit.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..core.photometry import brdf_product_nb

__all__ = [
    "const_rate_nb", "rk4_torque_free_nb", "apply_noise_nb", "perturb_rotvec_nb",
    "grp_rel_nb", "from_grp_rel_nb", "mag_kernel_nb", "bpf_predict_nb",
    "facet_mag_particles_nb", "weighted_param_stats_nb",
]


@nb.njit(cache=True, inline="always")
def _qmul_into(q, p, out):
    a0 = q[0] * p[0] - q[1] * p[1] - q[2] * p[2] - q[3] * p[3]
    a1 = q[0] * p[1] + p[0] * q[1] - (q[2] * p[3] - q[3] * p[2])
    a2 = q[0] * p[2] + p[0] * q[2] - (q[3] * p[1] - q[1] * p[3])
    a3 = q[0] * p[3] + p[0] * q[3] - (q[1] * p[2] - q[2] * p[1])
    out[0] = a0
    out[1] = a1
    out[2] = a2
    out[3] = a3


@nb.njit(cache=True, inline="always")
def _rotvec_q(tx, ty, tz, out):
    phi = math.sqrt(tx * tx + ty * ty + tz * tz)
    out[0] = math.cos(0.5 * phi)
    if phi > 1e-6:
        s = math.sin(0.5 * phi) / phi
    else:
        s = 0.5 - phi * phi / 48.0
    out[1] = s * tx
    out[2] = s * ty
    out[3] = s * tz


@nb.njit(cache=True, inline="always")
def _normalize(q):
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for j in range(4):
        q[j] /= n


@nb.njit(cache=True)
def const_rate_nb(Q, W, dt):
    """In place: ``Q[i] ← exp(W[i] dt) ⊗ Q[i]`` (exact constant-rate step; Q (N,4), W (N,3))."""
    N = Q.shape[0]
    dq = np.empty(4)
    qi = np.empty(4)
    for i in range(N):
        _rotvec_q(W[i, 0] * dt, W[i, 1] * dt, W[i, 2] * dt, dq)
        for j in range(4):
            qi[j] = Q[i, j]
        _qmul_into(dq, qi, Q[i])


@nb.njit(cache=True, inline="always")
def euler_wdot(w, J, Ji, out):
    """Torque-free Euler equations ``ω̇ = J⁻¹(−ω × Jω)`` (rad/s², body axes) into ``out`` (3,).

    ``w`` (3,) body rate rad/s, ``J``/``Ji`` (3,3) inertia kg·m² and its inverse.
    """
    h0 = J[0, 0] * w[0] + J[0, 1] * w[1] + J[0, 2] * w[2]
    h1 = J[1, 0] * w[0] + J[1, 1] * w[1] + J[1, 2] * w[2]
    h2 = J[2, 0] * w[0] + J[2, 1] * w[1] + J[2, 2] * w[2]
    r0 = -(w[1] * h2 - w[2] * h1)
    r1 = -(w[2] * h0 - w[0] * h2)
    r2 = -(w[0] * h1 - w[1] * h0)
    for a in range(3):
        out[a] = Ji[a, 0] * r0 + Ji[a, 1] * r1 + Ji[a, 2] * r2


@nb.njit(cache=True, inline="always")
def _euler_rhs(q, w, J, Ji, dq, dw):
    # q̇ = ½ [0, ω] ⊗ q (Bernard eq. 4.12);  ω̇ = J⁻¹(−ω × Jω) (eq. 4.13, torque free)
    dq[0] = -0.5 * (q[1] * w[0] + q[2] * w[1] + q[3] * w[2])
    dq[1] = 0.5 * (q[0] * w[0] - (w[1] * q[3] - w[2] * q[2]))
    dq[2] = 0.5 * (q[0] * w[1] - (w[2] * q[1] - w[0] * q[3]))
    dq[3] = 0.5 * (q[0] * w[2] - (w[0] * q[2] - w[1] * q[1]))
    euler_wdot(w, J, Ji, dw)


@nb.njit(cache=True, inline="always")
def _rk4_one(q, w, J, Ji, h, nsub, k1q, k2q, k3q, k4q, k1w, k2w, k3w, k4w, qt, wt):
    """In place on q (4,), w (3,): nsub RK4 steps of h s (torque free), renormalising q."""
    for _ in range(nsub):
        _euler_rhs(q, w, J, Ji, k1q, k1w)
        for j in range(4):
            qt[j] = q[j] + 0.5 * h * k1q[j]
        for j in range(3):
            wt[j] = w[j] + 0.5 * h * k1w[j]
        _euler_rhs(qt, wt, J, Ji, k2q, k2w)
        for j in range(4):
            qt[j] = q[j] + 0.5 * h * k2q[j]
        for j in range(3):
            wt[j] = w[j] + 0.5 * h * k2w[j]
        _euler_rhs(qt, wt, J, Ji, k3q, k3w)
        for j in range(4):
            qt[j] = q[j] + h * k3q[j]
        for j in range(3):
            wt[j] = w[j] + h * k3w[j]
        _euler_rhs(qt, wt, J, Ji, k4q, k4w)
        for j in range(4):
            q[j] += h / 6.0 * (k1q[j] + 2.0 * k2q[j] + 2.0 * k3q[j] + k4q[j])
        for j in range(3):
            w[j] += h / 6.0 * (k1w[j] + 2.0 * k2w[j] + 2.0 * k3w[j] + k4w[j])
        _normalize(q)


@nb.njit(cache=True, parallel=True)
def rk4_torque_free_nb(Q, W, J, Ji, dt, nsub):
    """In place: torque-free rigid-body propagation over ``dt`` s with ``nsub`` RK4 sub-steps.

    Q (N,4) inertial→body quaternions, W (N,3) body rates (rad/s), J / Ji (3,3) inertia (kg m²)
    and its inverse. The quaternion is renormalised after each sub-step. Parallel over chunks
    of particles (work arrays allocated once per chunk).
    """
    N = Q.shape[0]
    h = dt / nsub
    nch = _nchunks(N)
    for c in nb.prange(nch):
        lo = c * N // nch
        hi = (c + 1) * N // nch
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
            _rk4_one(Q[i], W[i], J, Ji, h, nsub, k1q, k2q, k3q, k4q, k1w, k2w, k3w, k4w, qt, wt)


@nb.njit(cache=True)
def _nchunks(N):
    """Number of work chunks for N particles (≥ 1; about 64 particles or more per chunk)."""
    c = N // 64
    if c < 1:
        c = 1
    if c > 256:
        c = 256
    return c


@nb.njit(cache=True)
def apply_noise_nb(Q, W, noise):
    """In place: ``Q[i] ← exp(noise[i,:3]) ⊗ Q[i]``, ``W[i] += noise[i,3:6]`` (noise (N,6), rad, rad/s)."""
    N = Q.shape[0]
    dq = np.empty(4)
    qi = np.empty(4)
    for i in range(N):
        _rotvec_q(noise[i, 0], noise[i, 1], noise[i, 2], dq)
        for j in range(4):
            qi[j] = Q[i, j]
        _qmul_into(dq, qi, Q[i])
        for j in range(3):
            W[i, j] += noise[i, 3 + j]


@nb.njit(cache=True)
def perturb_rotvec_nb(Q, theta):
    """New array ``exp(theta[i]) ⊗ Q[i]`` (theta (N,3) rotation vectors, rad, body axes)."""
    N = Q.shape[0]
    out = np.empty_like(Q)
    dq = np.empty(4)
    for i in range(N):
        _rotvec_q(theta[i, 0], theta[i, 1], theta[i, 2], dq)
        _qmul_into(dq, Q[i], out[i])
    return out


@nb.njit(cache=True)
def grp_rel_nb(Q, qref, a, f):
    """GRP (N,3) of ``δq_i = Q[i] ⊗ qref⁻¹`` with the sign making ``δq1 ≥ 0``."""
    N = Q.shape[0]
    out = np.empty((N, 3))
    qi = np.empty(4)
    qi[0] = qref[0]
    qi[1] = -qref[1]
    qi[2] = -qref[2]
    qi[3] = -qref[3]
    d = np.empty(4)
    for i in range(N):
        _qmul_into(Q[i], qi, d)
        if d[0] < 0.0:
            for j in range(4):
                d[j] = -d[j]
        den = a + d[0]
        out[i, 0] = f * d[1] / den
        out[i, 1] = f * d[2] / den
        out[i, 2] = f * d[3] / den
    return out


@nb.njit(cache=True)
def from_grp_rel_nb(P, qref, a, f):
    """Quaternions (N,4) ``grp2q(P[i]) ⊗ qref`` (inverse of :func:`grp_rel_nb`)."""
    N = P.shape[0]
    out = np.empty((N, 4))
    d = np.empty(4)
    for i in range(N):
        n2 = P[i, 0] * P[i, 0] + P[i, 1] * P[i, 1] + P[i, 2] * P[i, 2]
        q0 = (-a * n2 + f * math.sqrt(f * f + (1.0 - a * a) * n2)) / (f * f + n2)
        cc = (a + q0) / f
        d[0] = q0
        d[1] = cc * P[i, 0]
        d[2] = cc * P[i, 1]
        d[3] = cc * P[i, 2]
        _qmul_into(d, qref, out[i])
        _normalize(out[i])
    return out


@nb.njit(cache=True, inline="always")
def _qrot_into(q, v, out):
    """``out = A(q) v`` (inertial→body) without allocating."""
    tx = 2.0 * (q[2] * v[2] - q[3] * v[1])
    ty = 2.0 * (q[3] * v[0] - q[1] * v[2])
    tz = 2.0 * (q[1] * v[1] - q[2] * v[0])
    out[0] = v[0] - q[0] * tx + (q[2] * tz - q[3] * ty)
    out[1] = v[1] - q[0] * ty + (q[3] * tx - q[1] * tz)
    out[2] = v[2] - q[0] * tz + (q[1] * ty - q[2] * tx)


@nb.njit(cache=True, inline="always")
def _flux(q, s, o, normals, areas, ids, params, sb, ob):
    """Σ_i A_i (n̂·ŝ)⁺(n̂·ô)⁺ f_r,i for one attitude; sb, ob (3,) are work buffers."""
    _qrot_into(q, s, sb)
    _qrot_into(q, o, ob)
    acc = 0.0
    for fct in range(normals.shape[0]):
        mid = ids[fct]
        if mid < 0:
            continue
        nx = normals[fct, 0]
        ny = normals[fct, 1]
        nz = normals[fct, 2]
        if nx * sb[0] + ny * sb[1] + nz * sb[2] <= 0.0:
            continue
        if nx * ob[0] + ny * ob[1] + nz * ob[2] <= 0.0:
            continue
        acc += areas[fct] * brdf_product_nb(mid, params[fct], nx, ny, nz,
                                            sb[0], sb[1], sb[2], ob[0], ob[1], ob[2])
    return acc


@nb.njit(cache=True, parallel=True)
def mag_kernel_nb(Q, s, o, normals, areas, ids, params, offset):
    """Apparent magnitudes (S,) of attitudes Q (S,4) at one epoch.

    ``m = offset − 2.5 log10(Σ_i A_i (n̂·ŝ)⁺(n̂·ô)⁺ f_r,i)`` with ŝ, ô (3,) unit ECI directions
    object→Sun and object→observer, rotated into body axes by ``A(q)``; ``offset`` =
    m_sun + 5 log10(|r_obs|) + 5 log10(|r_sun|/au) (DESIGN.md magnitude equation); +inf where
    no light is reflected to the observer.
    """
    S = Q.shape[0]
    out = np.empty(S)
    nch = _nchunks(S)
    for c in nb.prange(nch):
        lo = c * S // nch
        hi = (c + 1) * S // nch
        sb = np.empty(3)
        ob = np.empty(3)
        for i in range(lo, hi):
            fl = _flux(Q[i], s, o, normals, areas, ids, params, sb, ob)
            out[i] = offset - 2.5 * math.log10(fl) if fl > 0.0 else np.inf
    return out


@nb.njit(cache=True, parallel=True)
def bpf_predict_nb(Q, W, dt, mode, J, Ji, nsub, noise, Lnoise, zeta, s, o, normals, areas, ids,
                   params, offset, m_out):
    """One fused bootstrap-PF prediction for every particle (in place on Q, W; fills m_out).

    mode 0: constant rate (controlled), 1: torque-free RK4 with ``nsub`` sub-steps
    (uncontrolled). ``noise`` (N,r) standard normals and ``Lnoise`` (6,r) a square root of the
    process-noise covariance: the sample ``Lnoise · noise[i]`` = [δθ (rad), δω (rad/s)] is
    applied after the deterministic step (``noise`` (0,r): none). ``zeta`` (N,3) or (0,3): ACS attitude noise (rad)
    applied to the attitude *only for the predicted measurement* (controlled model, Bernard
    eq. 7.8–7.11). ``m_out`` (N,) receives the predicted magnitudes (+inf: invisible). With
    ``s[0]`` NaN no magnitude is computed (propagation only). Parallel over chunks of
    particles; no allocation per particle.
    """
    N = Q.shape[0]
    h = dt / max(nsub, 1)
    use_noise = noise.shape[0] == N
    r = noise.shape[1]
    use_zeta = zeta.shape[0] == N
    predict = not np.isnan(s[0])
    nch = _nchunks(N)
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
                fl = _flux(qm, s, o, normals, areas, ids, params, sb, ob)
                m_out[i] = offset - 2.5 * math.log10(fl) if fl > 0.0 else np.inf


@nb.njit(cache=True)
def ess_tempered_nb(logw, ll, phi):
    """Effective sample size of the weights ``exp(logw + φ ll)`` (unnormalised logs).

    Two passes, no temporary arrays: ``N_eff = (Σ e^{a−m})² / Σ e^{2(a−m)}`` with
    ``a = logw + φ ll`` (φ = 0 ignores ``ll``; −inf entries count as zero weight), m = max a.
    Returns 0 when every weight is zero.
    """
    N = logw.shape[0]
    m = -np.inf
    for i in range(N):
        a = logw[i] + phi * ll[i] if phi != 0.0 else logw[i]
        if a > m:
            m = a
    if m == -np.inf or np.isnan(m):
        return 0.0
    s1 = 0.0
    s2 = 0.0
    for i in range(N):
        a = logw[i] + phi * ll[i] if phi != 0.0 else logw[i]
        if a > -np.inf:
            e = math.exp(a - m)
            s1 += e
            s2 += e * e
    return s1 * s1 / s2


@nb.njit(cache=True)
def innovation_loglik_nb(logw, mpred, y, sig, ll):
    """Prior-weighted innovation statistics and per-particle log-likelihoods (one epoch).

    Fills ``ll[i] = −½ ((y − m_i)/σ)²`` (−inf where ``m_i`` is not finite: the particle
    reflects no light). Returns ``(ŷ, var_m, ok)``: the mean and variance of the finite
    predictions under the prior weights ``exp(logw)`` (renormalised over them); ``ok`` False
    when no prediction is finite. Magnitudes, mag².
    """
    N = logw.shape[0]
    mx = -np.inf
    for i in range(N):
        if logw[i] > mx:
            mx = logw[i]
    s0 = 0.0
    s1 = 0.0
    for i in range(N):
        m = mpred[i]
        if np.isfinite(m):
            e = math.exp(logw[i] - mx) if mx > -np.inf else 1.0
            s0 += e
            s1 += e * m
            r = (y - m) / sig
            ll[i] = -0.5 * r * r
        else:
            ll[i] = -np.inf
    if not s0 > 0.0:
        return np.nan, np.nan, False
    mean = s1 / s0
    s2 = 0.0
    for i in range(N):
        m = mpred[i]
        if np.isfinite(m):
            e = math.exp(logw[i] - mx) if mx > -np.inf else 1.0
            s2 += e * (m - mean) * (m - mean)
    return mean, s2 / s0, True


@nb.njit(cache=True)
def add_normalize_nb(logw, ll, phi, w):
    """In place ``logw ← logw + φ ll`` then normalise (log-sum-exp); fills ``w = exp(logw)``.

    Returns ``(N_eff, ok)`` with ``N_eff = 1/Σ w²``; ``ok`` False (and logw, w untouched
    beyond the addition) when every weight is zero. φ = 0 adds nothing.
    """
    N = logw.shape[0]
    mx = -np.inf
    for i in range(N):
        if phi != 0.0:
            logw[i] += phi * ll[i]
        if logw[i] > mx:
            mx = logw[i]
    if not mx > -np.inf:
        return 0.0, False
    s = 0.0
    for i in range(N):
        e = math.exp(logw[i] - mx)
        w[i] = e
        s += e
    lse = mx + math.log(s)
    s2 = 0.0
    for i in range(N):
        logw[i] -= lse
        w[i] /= s
        s2 += w[i] * w[i]
    return 1.0 / s2, True


@nb.njit(cache=True)
def weighted_stats_nb(dp, W, w):
    """Weighted mean (6,) and covariance (6,6) of the rows [dp (N,3), W (N,3)] (Σ w = 1)."""
    N = dp.shape[0]
    mean = np.zeros(6)
    for i in range(N):
        for j in range(3):
            mean[j] += w[i] * dp[i, j]
            mean[3 + j] += w[i] * W[i, j]
    C = np.zeros((6, 6))
    x = np.empty(6)
    for i in range(N):
        for j in range(3):
            x[j] = dp[i, j] - mean[j]
            x[3 + j] = W[i, j] - mean[3 + j]
        wi = w[i]
        for a in range(6):
            xa = wi * x[a]
            for b in range(a + 1):
                C[a, b] += xa * x[b]
    for a in range(6):
        for b in range(a):
            C[b, a] = C[a, b]
    return mean, C


@nb.njit(cache=True, inline="always")
def _fill_facet_arrays(z, facet, kind_col, logit, areas0, params0, ar, pr):
    """Facet areas ``ar`` (F,) m² and BRDF parameters ``pr`` (F,P) of one Model 3 state z (D,).

    Starts from the nominal ``areas0``/``params0`` and overwrites the estimated entries with
    ``p = 1/(1+e^{−z})`` (``logit[d]``) or ``e^{z}``; ``kind_col[d] == 3`` is an area, otherwise
    the BRDF parameter column of facet ``facet[d]``.
    """
    F, P = params0.shape
    for f in range(F):
        ar[f] = areas0[f]
        for j in range(P):
            pr[f, j] = params0[f, j]
    for d in range(z.shape[0]):
        zz = z[d]
        v = 1.0 / (1.0 + math.exp(-zz)) if logit[d] else math.exp(zz)
        if kind_col[d] == 3:
            ar[facet[d]] = v
        else:
            pr[facet[d], kind_col[d]] = v


@nb.njit(cache=True, parallel=True)
def facet_mag_particles_nb(Q, zeta, Z, facet, kind_col, logit, s, o, normals, areas0, ids,
                           params0, offset, m_out):
    """Apparent magnitudes with per-particle facet parameters (Model 3, Bernard ch. 8).

    ``m_out[i] = offset − 2.5 log10 Σ_f A_if (n̂_f·ŝ)⁺(n̂_f·ô)⁺ f_r,f`` (DESIGN.md magnitude
    equation) where particle i's facet arrays are the shape's ``areas0`` (F,) m² and packed
    BRDF rows ``params0`` (F,P) with the estimated entries replaced by ``p(Z[i])``: state d
    sets parameter ``kind_col[d]`` (0 ξ, 1 a = F0, 2 m (Beckmann slope) → ``params[f,kc]``;
    3 → area A_f, m²) of facet ``facet[d]`` to ``1/(1+e^{−z})`` (``logit[d]``) or ``e^{z}``.

    Q (N,4) inertial→body quaternions, or (1,4) shared by every particle (attitude known);
    ``zeta`` (N,3) ACS jitter rotation vectors (rad) applied as ``exp(ζ_i) ⊗ q_i`` for the
    prediction only, or (0,3); Z (N,D) unbounded states, or (1,D) shared; s, o (3,) unit
    object→Sun / object→observer directions in ECI; normals (F,3) body axes; ids (F,) BRDF
    model ids. The flux loop is the attitude-only kernel's (:func:`bpf_predict_nb`), so with
    ``p(Z[i])`` equal to the shape's values the two agree to round-off. +inf where no light
    reaches the observer. Parallel over chunks of particles; work buffers per chunk.
    """
    N = m_out.shape[0]
    F = normals.shape[0]
    P = params0.shape[1]
    D = facet.shape[0]
    qall = Q.shape[0] == N
    zall = Z.shape[0] == N
    use_zeta = zeta.shape[0] == N
    nch = _nchunks(N)
    for c in nb.prange(nch):
        lo = c * N // nch
        hi = (c + 1) * N // nch
        ar = np.empty(F)
        pr = np.empty((F, P))
        sb = np.empty(3)
        ob = np.empty(3)
        dq = np.empty(4)
        qm = np.empty(4)
        for i in range(lo, hi):
            iq = i if qall else 0
            iz = i if zall else 0
            _fill_facet_arrays(Z[iz], facet, kind_col, logit, areas0, params0, ar, pr)
            if use_zeta:
                _rotvec_q(zeta[i, 0], zeta[i, 1], zeta[i, 2], dq)
                _qmul_into(dq, Q[iq], qm)
            else:
                for j in range(4):
                    qm[j] = Q[iq, j]
            fl = _flux(qm, s, o, normals, ar, ids, pr, sb, ob)
            m_out[i] = offset - 2.5 * math.log10(fl) if fl > 0.0 else np.inf


@nb.njit(cache=True)
def weighted_param_stats_nb(Z, w, logit):
    """Weighted mean and variance of unbounded states Z (N,D) and of their physical values.

    ``p = 1/(1+e^{−z})`` where ``logit[d]`` else ``e^{z}``; weights w (N,) sum to 1.
    Returns ``(z_mean, z_var, p_mean, p_var)``, each (D,).
    """
    N, D = Z.shape
    zm = np.zeros(D)
    pm = np.zeros(D)
    z2 = np.zeros(D)
    p2 = np.zeros(D)
    for i in range(N):
        wi = w[i]
        if wi == 0.0:
            continue
        for d in range(D):
            zz = Z[i, d]
            pp = 1.0 / (1.0 + math.exp(-zz)) if logit[d] else math.exp(zz)
            zm[d] += wi * zz
            pm[d] += wi * pp
    for i in range(N):
        wi = w[i]
        if wi == 0.0:
            continue
        for d in range(D):
            zz = Z[i, d]
            pp = 1.0 / (1.0 + math.exp(-zz)) if logit[d] else math.exp(zz)
            z2[d] += wi * (zz - zm[d]) ** 2
            p2[d] += wi * (pp - pm[d]) ** 2
    return zm, z2, pm, p2


@nb.njit(cache=True, parallel=True)
def facet_loglik_history_nb(Z, kmax, phi_last, Qs, S, O, offs, y, sig, facet, kind_col, logit,
                            normals, areas0, ids, params0, out):
    """Log-likelihood of each particle's facet states over the measurement history.

    ``out[i] = Σ_{j<kmax} ℓ_j(Z[i]) + φ_last ℓ_kmax(Z[i])`` with
    ``ℓ_j = −½ ((y_j − m_j)/σ_j)²`` (m_j the magnitude of :func:`facet_mag_particles_nb` at the
    known attitude ``Qs[j]``; ``ℓ_j = −inf`` when m_j = +inf; epochs with a non-finite
    ``y_j`` are skipped). Qs (n,4) known inertial→body attitudes, S, O (n,3) unit ECI
    object→Sun / object→observer, offs (n,) magnitude offsets, y, sig (n,) mag. Used by the
    resample-move step of the BPF's attitude-known mode. Parallel over chunks of particles.
    """
    N = Z.shape[0]
    F = normals.shape[0]
    P = params0.shape[1]
    D = facet.shape[0]
    nch = _nchunks(N)
    for c in nb.prange(nch):
        lo = c * N // nch
        hi = (c + 1) * N // nch
        ar = np.empty(F)
        pr = np.empty((F, P))
        sb = np.empty(3)
        ob = np.empty(3)
        for i in range(lo, hi):
            _fill_facet_arrays(Z[i], facet, kind_col, logit, areas0, params0, ar, pr)
            acc = 0.0
            for j in range(kmax + 1):
                wj = 1.0 if j < kmax else phi_last
                if wj == 0.0 or not np.isfinite(y[j]):
                    continue
                fl = _flux(Qs[j], S[j], O[j], normals, ar, ids, pr, sb, ob)
                if not fl > 0.0:
                    acc = -np.inf
                    break
                r = (y[j] - (offs[j] - 2.5 * math.log10(fl))) / sig[j]
                acc += -0.5 * wj * r * r
            out[i] = acc


@nb.njit(cache=True)
def mean_cov_nb(E):
    """Equal-weight mean (D,) and covariance (D,D) (divisor N) of the rows of E (N,D).

    Serial loops instead of BLAS: the clouds are thin (D ≤ a few tens) and multithreaded BLAS
    on a busy machine costs far more than the arithmetic.
    """
    N, D = E.shape
    mean = np.zeros(D)
    for i in range(N):
        for d in range(D):
            mean[d] += E[i, d]
    for d in range(D):
        mean[d] /= N
    C = np.zeros((D, D))
    x = np.empty(D)
    for i in range(N):
        for d in range(D):
            x[d] = E[i, d] - mean[d]
        for a in range(D):
            xa = x[a]
            for b in range(a + 1):
                C[a, b] += xa * x[b]
    for a in range(D):
        for b in range(a + 1):
            C[a, b] /= N
            C[b, a] = C[a, b]
    return mean, C


@nb.njit(cache=True)
def affine_rows_nb(X, M, a, c, base, out):
    """``out[i] = a · base[i] + c + X[i] @ Mᵀ`` for X (N,r), M (D,r), base (N,D), c (D,).

    (Serial; the Liu–West jitter and the Metropolis proposal of the BPF's extra states.)
    """
    N, r = X.shape
    D = M.shape[0]
    for i in range(N):
        for d in range(D):
            acc = a * base[i, d] + c[d]
            for j in range(r):
                acc += M[d, j] * X[i, j]
            out[i, d] = acc
