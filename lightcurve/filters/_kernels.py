"""Numba kernels of the attitude filters (plain float64 arrays; no validation).

Conventions: quaternions scalar first, inertial→body passive (``v_b = A(q) v_I``); body rates
ω in body axes, rad/s; the attitude *error* of a state ``q`` relative to a reference ``q_ref``
is ``δq = q ⊗ q_ref⁻¹`` (so ``q = δq ⊗ q_ref``), expressed as a GRP ``p = f δq_v/(a + δq1)``
(Bernard eq. 3.28, default a = 1, f = 4) with the sign of ``δq`` chosen so that ``δq1 ≥ 0``,
or as a rotation vector (small-angle error, ``δq = [cos(|θ|/2), θ̂ sin(|θ|/2)]``).

Every ``prange`` loop is over independent particles / sigma points, so the results do not
depend on the number of threads (only the heavy kernels — magnitudes, RK4 — are compiled
parallel; the cheap chart maps run serially, because waking a
thread pool costs more than they do); random numbers are drawn by the caller from a
``numpy.random.Generator`` and passed in, which keeps runs reproducible bit for bit.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..photometry.kernels import COOK_TORRANCE, brdf_product_nb, ct_product_fresnel, fresnel_ct

__all__ = [
    "const_rate_nb", "rk4_torque_free_nb", "apply_noise_nb", "perturb_rotvec_nb",
    "grp_rel_nb", "from_grp_rel_nb", "mag_kernel_nb",
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


@nb.njit(cache=True)
def flux_invariants(s, o, ids, params, Fr):
    """Attitude-independent parts of the facet sum at one geometry: returns ``(ĥ (3,), c)``
    with ĥ = (ŝ+ô)/|ŝ+ô| (ECI) and c = ô·ĥ, and fills ``Fr[f]`` with the Cook–Torrance
    Fresnel factor F(c, F0_f) of every Cook–Torrance facet (0 for the others). c = −1 when
    ŝ = −ô (no half vector; no facet sees both)."""
    hx = s[0] + o[0]
    hy = s[1] + o[1]
    hz = s[2] + o[2]
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    h = np.zeros(3)
    c = -1.0
    if hn > 0.0:
        h[0] = hx / hn
        h[1] = hy / hn
        h[2] = hz / hn
        c = o[0] * h[0] + o[1] * h[1] + o[2] * h[2]
    for f in range(ids.shape[0]):
        Fr[f] = fresnel_ct(c, params[f, 1]) if (ids[f] == COOK_TORRANCE and c > 0.0) else 0.0
    return h, c


@nb.njit(cache=True, inline="always")
def _flux_pre(q, s, o, h, c, Fr, normals, areas, ids, params, sb, ob, hb):
    """:func:`_flux` with the invariants of :func:`flux_invariants` precomputed (the same
    sum; Cook–Torrance through :func:`~lightcurve.photometry.kernels.ct_product_fresnel`,
    other models through ``brdf_product_nb``)."""
    _qrot_into(q, s, sb)
    _qrot_into(q, o, ob)
    _qrot_into(q, h, hb)
    acc = 0.0
    for fct in range(normals.shape[0]):
        mid = ids[fct]
        if mid < 0:
            continue
        nx = normals[fct, 0]
        ny = normals[fct, 1]
        nz = normals[fct, 2]
        ns = nx * sb[0] + ny * sb[1] + nz * sb[2]
        if ns <= 0.0:
            continue
        no = nx * ob[0] + ny * ob[1] + nz * ob[2]
        if no <= 0.0:
            continue
        if mid == COOK_TORRANCE:
            nh = nx * hb[0] + ny * hb[1] + nz * hb[2]
            p = params[fct]
            acc += areas[fct] * ct_product_fresnel(ns, no, nh, c, Fr[fct], p[0], p[1], p[2])
        else:
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
