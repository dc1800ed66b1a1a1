"""Numba kernels of the bootstrap attitude particle filter (Bernard 2021 tables 7.7–7.11).

Particles are rows of ``Q`` (N,4) inertial→body quaternions (scalar first) and ``W`` (N,3) body
rates (rad/s). The attitude chart of a cloud about a reference ``q_ref`` is the GRP
(Bernard eq. 7.1, a = 1, f = 4) of ``δq_i = q_i ⊗ q_ref⁻¹`` with the sign ``δq1 ≥ 0``; a chart
buffer ``X`` (N, 6 + e) holds ``[δp_i, ω_i, extra states]`` per row. Model 3 particles carry
facet parameters ``Z`` (N, D) (Bernard ch. 8).

The rotation algebra, the rigid-body step and the BRDFs are the core's
(:mod:`lightcurve.core.rotations`, :mod:`lightcurve.core.dynamics`,
:mod:`lightcurve.core.photometry`). Every kernel is parallel over particles (``prange``),
allocation-free per particle, and its result does not depend on the number of threads
(reductions sum fixed chunks in order, :func:`lightcurve.core.particles.n_chunks`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..core.dynamics import const_rate_xyz, mat9, rk4_step_xyz
from ..core.particles import chunk_bounds, chunk_sums, chunked_sum_kernel, n_chunks
from ..core.photometry import (COOK_TORRANCE, COOK_TORRANCE_THESIS, beckmann_exponent,
                               brdf_product_nb, cook_torrance_fresnel_exp_xyz, facet_flux_nb,
                               facet_sum_fresnel_xyz, fresnel_xyz)
from ..core.rotations import grp2q_xyz, qmul_xyz, qrot_xyz_nb, rotvec2q_sc_xyz, rotvec2q_xyz
from .facet_states import fill_facet_arrays_nb, from_unbounded_xyz

__all__ = ["bpf_predict_nb", "predict_work_size", "flux_invariants", "argmax_weights",
           "grp_weighted_mean", "chart_rows", "chart_stats", "grp_compose", "grp_times_rows",
           "roughen_chart", "roughen_compose", "liu_west_attitude", "min_abs_residual",
           "facet_mag_particles_nb", "weighted_param_stats_nb", "facet_loglik_history_nb"]


@nb.njit(cache=True)
def flux_invariants(s, o, ids, params, Fr):
    """Attitude-independent parts of the facet sum at one geometry: returns ``(ĥ, c)`` with
    ĥ = (ŝ+ô)/|ŝ+ô| (3-tuple, ECI) and c = ô·ĥ, and fills ``Fr[f]`` with the Cook–Torrance
    Fresnel factor F(c, F0_f) (:func:`~lightcurve.core.photometry.fresnel_xyz`) of every
    Cook–Torrance facet (0 for the others). c = −1 when ŝ = −ô (no facet sees both)."""
    hx = s[0] + o[0]
    hy = s[1] + o[1]
    hz = s[2] + o[2]
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    h = (0.0, 0.0, 0.0)
    c = -1.0
    if hn > 0.0:
        h = (hx / hn, hy / hn, hz / hn)
        c = o[0] * h[0] + o[1] * h[1] + o[2] * h[2]
    for f in range(ids.shape[0]):
        ct = ids[f] == COOK_TORRANCE or ids[f] == COOK_TORRANCE_THESIS
        Fr[f] = fresnel_xyz(c, params[f, 1])[0] if (ct and c > 0.0) else 0.0
    return h, c


@nb.njit(cache=True, inline="always")
def _flux_pre(q0, q1, q2, q3, s, o, h, c, Fr, normals, areas, ids, params):
    """Facet sum ``Σ_i A_i (n̂·ŝ)⁺(n̂·ô)⁺ f_r,i`` of one attitude with the invariants of
    :func:`flux_invariants` (the sum of :func:`~lightcurve.core.photometry.facet_flux_nb`;
    Cook–Torrance through ``cook_torrance_fresnel_xyz`` with the epoch's F, the other models
    through ``brdf_product_nb``)."""
    sx, sy, sz = qrot_xyz_nb(q0, q1, q2, q3, s[0], s[1], s[2])
    ox, oy, oz = qrot_xyz_nb(q0, q1, q2, q3, o[0], o[1], o[2])
    hx, hy, hz = qrot_xyz_nb(q0, q1, q2, q3, h[0], h[1], h[2])
    return facet_sum_fresnel_xyz(sx, sy, sz, ox, oy, oz, hx, hy, hz, c, Fr, normals, areas, ids,
                                 params)


@nb.njit(cache=True, inline="always")
def _grp_of_xyz(q, r, a, f):
    """GRP 3-tuple of ``q ⊗ r⁻¹`` (Bernard eq. 7.100 and 7.1) with the sign of the scalar part
    made ≥ 0."""
    d0, d1, d2, d3 = qmul_xyz(q[0], q[1], q[2], q[3], r[0], -r[1], -r[2], -r[3])
    if d0 < 0.0:
        d0, d1, d2, d3 = -d0, -d1, -d2, -d3
    den = a + d0
    return f * d1 / den, f * d2 / den, f * d3 / den


@nb.njit(cache=True, inline="always")
def _grp_of(q, r, a, f, out):
    """:func:`_grp_of_xyz` into ``out`` (3,)."""
    out[0], out[1], out[2] = _grp_of_xyz(q, r, a, f)


@nb.njit(cache=True, inline="always")
def _grp_times(p0, p1, p2, a, f, r, out):
    """``out = grp2q(p) ⊗ r`` (Bernard eq. 7.105 / 7.108), renormalised."""
    d0, d1, d2, d3 = grp2q_xyz(p0, p1, p2, a, f)
    e0, e1, e2, e3 = qmul_xyz(d0, d1, d2, d3, r[0], r[1], r[2], r[3])
    n = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
    out[0] = e0 / n
    out[1] = e1 / n
    out[2] = e2 / n
    out[3] = e3 / n


@nb.njit(cache=True, inline="always")
def _noise_sample(noise, Lnoise, i):
    """The process-noise sample ``Lnoise · noise[i]`` = [δθ (rad), δω (rad/s)] → 6-tuple."""
    v0 = 0.0
    v1 = 0.0
    v2 = 0.0
    v3 = 0.0
    v4 = 0.0
    v5 = 0.0
    for cc in range(noise.shape[1]):
        z = noise[i, cc]
        v0 += Lnoise[0, cc] * z
        v1 += Lnoise[1, cc] * z
        v2 += Lnoise[2, cc] * z
        v3 += Lnoise[3, cc] * z
        v4 += Lnoise[4, cc] * z
        v5 += Lnoise[5, cc] * z
    return v0, v1, v2, v3, v4, v5


@nb.njit(cache=True, inline="always")
def _rk4_steps(q0, q1, q2, q3, w0, w1, w2, h, nsub, Jt, Kt):
    """``nsub`` steps of the core's RK4 of the torque-free body → (q, ω) 7-tuple."""
    for _ in range(nsub):
        q0, q1, q2, q3, w0, w1, w2 = rk4_step_xyz(q0, q1, q2, q3, w0, w1, w2, h, Jt, Kt, None,
                                                  None, None)
    return q0, q1, q2, q3, w0, w1, w2


@nb.njit(cache=True, inline="always")
def predict_row(i, Q, W, dt, mode, h, nsub, Jt, Kt, noise, Lnoise, use_noise, zeta, use_zeta,
                predict, s, o, hI, cI, Fr, normals, areas, ids, params, offset, m_out):
    """The prediction of particle i: propagate row i of Q, W over dt (``h = dt/nsub``, ``Jt``,
    ``Kt`` the inertia and its inverse as 9-tuples), add the process noise, and for ``predict``
    write its magnitude into ``m_out[i]``. The CUDA kernel of :mod:`lightcurve.filters.bpf_gpu`
    runs it per thread; :func:`bpf_predict_nb`'s block passes give the same bits."""
    q0, q1, q2, q3 = Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3]
    w0, w1, w2 = W[i, 0], W[i, 1], W[i, 2]
    if dt != 0.0:
        if mode == 0:
            q0, q1, q2, q3 = const_rate_xyz(q0, q1, q2, q3, w0, w1, w2, dt)
        else:
            q0, q1, q2, q3, w0, w1, w2 = _rk4_steps(q0, q1, q2, q3, w0, w1, w2, h, nsub, Jt, Kt)
    if use_noise:
        v0, v1, v2, v3, v4, v5 = _noise_sample(noise, Lnoise, i)
        d0, d1, d2, d3 = rotvec2q_xyz(v0, v1, v2)
        q0, q1, q2, q3 = qmul_xyz(d0, d1, d2, d3, q0, q1, q2, q3)
        w0 += v3
        w1 += v4
        w2 += v5
    n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    q0 /= n
    q1 /= n
    q2 /= n
    q3 /= n
    Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3] = q0, q1, q2, q3
    W[i, 0], W[i, 1], W[i, 2] = w0, w1, w2
    if predict:
        if use_zeta:
            d0, d1, d2, d3 = rotvec2q_xyz(zeta[i, 0], zeta[i, 1], zeta[i, 2])
            q0, q1, q2, q3 = qmul_xyz(d0, d1, d2, d3, q0, q1, q2, q3)
        fl = _flux_pre(q0, q1, q2, q3, s, o, hI, cI, Fr, normals, areas, ids, params)
        m_out[i] = offset - 2.5 * math.log10(fl) if fl > 0.0 else np.inf


_BLOCK = 128
"""Particles per block of the vectorised prediction (:func:`bpf_predict_nb`)."""
# scratch rows of _BLOCK doubles (one set per chunk): the block's attitude, rate, jitter and
# exp(jitter) copied out of the (N, k) arrays; the rate step's φ, sin φ/2, cos φ/2; the
# process-noise sample (6) and its φ, sin, cos; the jitter's φ, sin, cos; the body-frame ŝ, ô,
# ĥ (9); one facet's n̂·ŝ, n̂·ô, n̂·ĥ, Beckmann exponent and its exp; the facet sum
(_Q, _W, _Z, _D, _PHI, _SN, _CS, _V0, _NPHI, _NSN, _NCS, _ZPHI, _ZSN, _ZCS, _SB, _NS, _NO,
 _NH, _ARG, _EX, _ACC) = (0, 4, 7, 10, 14, 15, 16, 17, 23, 24, 25, 26, 27, 28, 29, 38, 39, 40,
                          41, 42, 43)
_SLOTS = _ACC + 1
"""Scratch rows per chunk of :func:`bpf_predict_nb` (the facet sum is the last)."""


def predict_work_size(N):
    """Length of the scratch buffer :func:`bpf_predict_nb` needs for N particles."""
    return n_chunks(N) * _SLOTS * _BLOCK


@nb.njit(cache=True, inline="always")
def _row(k, j):
    """Index of particle j of the block in scratch row k."""
    return k * _BLOCK + j


@nb.njit(cache=True, inline="always")
def _copy_in(A, b0, m, ncol, w, k):
    """Scalar pass: columns of rows b0…b0+m of A (N, ncol) into scratch rows k… ."""
    for j in range(m):
        for c in range(ncol):
            w[_row(k + c, j)] = A[b0 + j, c]


@nb.njit(cache=True, inline="always")
def _sincos_half(w, phi, sn, cs, m):
    """Scalar libm pass: rows sn, cs ← sin, cos of half of row phi."""
    for j in range(m):
        x = 0.5 * w[_row(phi, j)]
        w[_row(sn, j)] = math.sin(x)
        w[_row(cs, j)] = math.cos(x)


@nb.njit(cache=True, inline="always")
def _norm3_into(w, k, dt, out, m):
    """Vector pass: row out ← |dt · (rows k, k+1, k+2)|."""
    for j in range(m):
        tx = w[_row(k, j)] * dt
        ty = w[_row(k + 1, j)] * dt
        tz = w[_row(k + 2, j)] * dt
        w[_row(out, j)] = math.sqrt(tx * tx + ty * ty + tz * tz)


@nb.njit(cache=True, inline="always")
def _pass_step(w, m, dt, rate, normalise):
    """Vector pass on the attitude rows: ``q ← exp(ω dt) ⊗ q`` (``rate``), then renormalised
    (``normalise``)."""
    for j in range(m):
        q0 = w[_row(_Q, j)]
        q1 = w[_row(_Q + 1, j)]
        q2 = w[_row(_Q + 2, j)]
        q3 = w[_row(_Q + 3, j)]
        if rate:
            d0, d1, d2, d3 = rotvec2q_sc_xyz(w[_row(_W, j)] * dt, w[_row(_W + 1, j)] * dt,
                                           w[_row(_W + 2, j)] * dt, w[_row(_PHI, j)],
                                           w[_row(_SN, j)], w[_row(_CS, j)])
            q0, q1, q2, q3 = qmul_xyz(d0, d1, d2, d3, q0, q1, q2, q3)
        if normalise:
            n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
            q0 /= n
            q1 /= n
            q2 /= n
            q3 /= n
        w[_row(_Q, j)] = q0
        w[_row(_Q + 1, j)] = q1
        w[_row(_Q + 2, j)] = q2
        w[_row(_Q + 3, j)] = q3


@nb.njit(cache=True, inline="always")
def _pass_noise(noise, Lnoise, b0, m, w):
    """Scalar pass: the process-noise samples ``Lnoise · noise[i]`` into rows _V0…_V0+5 and
    the rotation angle of their attitude part into _NPHI."""
    for j in range(m):
        v0, v1, v2, v3, v4, v5 = _noise_sample(noise, Lnoise, b0 + j)
        w[_row(_V0, j)] = v0
        w[_row(_V0 + 1, j)] = v1
        w[_row(_V0 + 2, j)] = v2
        w[_row(_V0 + 3, j)] = v3
        w[_row(_V0 + 4, j)] = v4
        w[_row(_V0 + 5, j)] = v5
        w[_row(_NPHI, j)] = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)


@nb.njit(cache=True, inline="always")
def _pass_noise_apply(w, m):
    """Vector pass: ``q ← exp(δθ) ⊗ q`` of the process noise on the attitude rows,
    renormalised."""
    for j in range(m):
        d0, d1, d2, d3 = rotvec2q_sc_xyz(w[_row(_V0, j)], w[_row(_V0 + 1, j)],
                                       w[_row(_V0 + 2, j)], w[_row(_NPHI, j)],
                                       w[_row(_NSN, j)], w[_row(_NCS, j)])
        q0, q1, q2, q3 = qmul_xyz(d0, d1, d2, d3, w[_row(_Q, j)], w[_row(_Q + 1, j)],
                                  w[_row(_Q + 2, j)], w[_row(_Q + 3, j)])
        n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        w[_row(_Q, j)] = q0 / n
        w[_row(_Q + 1, j)] = q1 / n
        w[_row(_Q + 2, j)] = q2 / n
        w[_row(_Q + 3, j)] = q3 / n


@nb.njit(cache=True, inline="always")
def _pass_copy_out(Q, W, b0, m, use_noise, w):
    """Scalar pass: the attitude rows back into Q; the rate noise added to W."""
    for j in range(m):
        i = b0 + j
        Q[i, 0] = w[_row(_Q, j)]
        Q[i, 1] = w[_row(_Q + 1, j)]
        Q[i, 2] = w[_row(_Q + 2, j)]
        Q[i, 3] = w[_row(_Q + 3, j)]
        if use_noise:
            W[i, 0] += w[_row(_V0 + 3, j)]
            W[i, 1] += w[_row(_V0 + 4, j)]
            W[i, 2] += w[_row(_V0 + 5, j)]


@nb.njit(cache=True, inline="always")
def _pass_jitter_q(w, m):
    """Vector pass: rows _D…_D+3 ← exp(ζ) of the jitter rows (φ, sin, cos given)."""
    for j in range(m):
        d0, d1, d2, d3 = rotvec2q_sc_xyz(w[_row(_Z, j)], w[_row(_Z + 1, j)], w[_row(_Z + 2, j)],
                                       w[_row(_ZPHI, j)], w[_row(_ZSN, j)], w[_row(_ZCS, j)])
        w[_row(_D, j)] = d0
        w[_row(_D + 1, j)] = d1
        w[_row(_D + 2, j)] = d2
        w[_row(_D + 3, j)] = d3


@nb.njit(cache=True, inline="always")
def _pass_copy_dq(dq, b0, m, w):
    """Scalar pass: the rows _D…_D+3 into dq."""
    for j in range(m):
        i = b0 + j
        dq[i, 0] = w[_row(_D, j)]
        dq[i, 1] = w[_row(_D + 1, j)]
        dq[i, 2] = w[_row(_D + 2, j)]
        dq[i, 3] = w[_row(_D + 3, j)]


@nb.njit(cache=True, inline="always")
def _pass_body(m, jitter, s, o, hI, w):
    """Vector pass: the measured attitude ``exp(ζ) ⊗ q`` (``jitter``) and ŝ, ô, ĥ in its body
    frame into rows _SB…_SB+8; the facet-sum row zeroed."""
    for j in range(m):
        q0 = w[_row(_Q, j)]
        q1 = w[_row(_Q + 1, j)]
        q2 = w[_row(_Q + 2, j)]
        q3 = w[_row(_Q + 3, j)]
        if jitter:
            q0, q1, q2, q3 = qmul_xyz(w[_row(_D, j)], w[_row(_D + 1, j)], w[_row(_D + 2, j)],
                                      w[_row(_D + 3, j)], q0, q1, q2, q3)
        sx, sy, sz = qrot_xyz_nb(q0, q1, q2, q3, s[0], s[1], s[2])
        ox, oy, oz = qrot_xyz_nb(q0, q1, q2, q3, o[0], o[1], o[2])
        hx, hy, hz = qrot_xyz_nb(q0, q1, q2, q3, hI[0], hI[1], hI[2])
        w[_row(_SB, j)] = sx
        w[_row(_SB + 1, j)] = sy
        w[_row(_SB + 2, j)] = sz
        w[_row(_SB + 3, j)] = ox
        w[_row(_SB + 4, j)] = oy
        w[_row(_SB + 5, j)] = oz
        w[_row(_SB + 6, j)] = hx
        w[_row(_SB + 7, j)] = hy
        w[_row(_SB + 8, j)] = hz
        w[_row(_ACC, j)] = 0.0


@nb.njit(cache=True, inline="always")
def _pass_ct_cosines(nx, ny, nz, mm, m, w):
    """Vector pass: n̂·ŝ, n̂·ô, n̂·ĥ of one facet and its Beckmann exponent (rows _NS…_ARG)."""
    for j in range(m):
        ns = nx * w[_row(_SB, j)] + ny * w[_row(_SB + 1, j)] + nz * w[_row(_SB + 2, j)]
        no = nx * w[_row(_SB + 3, j)] + ny * w[_row(_SB + 4, j)] + nz * w[_row(_SB + 5, j)]
        nh = nx * w[_row(_SB + 6, j)] + ny * w[_row(_SB + 7, j)] + nz * w[_row(_SB + 8, j)]
        w[_row(_NS, j)] = ns
        w[_row(_NO, j)] = no
        w[_row(_NH, j)] = nh
        w[_row(_ARG, j)] = beckmann_exponent(nh, mm)


@nb.njit(cache=True, inline="always")
def _pass_ct_exp(cI, m, w):
    """Scalar libm pass: the Beckmann exponentials where the facet is lit, seen and the
    specular term defined (``n̂·ĥ > 0``, ``c > 0``), else 0 (unused). (Measured: faster than
    gathering the lit particles first to avoid the branch, and than an exp for every
    particle.)"""
    for j in range(m):
        e = 0.0
        if (w[_row(_NS, j)] > 0.0 and w[_row(_NO, j)] > 0.0 and w[_row(_NH, j)] > 0.0
                and cI > 0.0):
            e = math.exp(w[_row(_ARG, j)])
        w[_row(_EX, j)] = e


@nb.njit(cache=True, inline="always")
def _pass_ct_add(ar, xi, a, mm, Ff, th, cI, m, w):
    """Vector pass: add ``A (n̂·ŝ)(n̂·ô) f_r`` of one Cook–Torrance facet to the facet sum where
    it is lit and seen (:func:`~lightcurve.core.photometry.cook_torrance_fresnel_exp_xyz`)."""
    for j in range(m):
        ns = w[_row(_NS, j)]
        no = w[_row(_NO, j)]
        P = cook_torrance_fresnel_exp_xyz(ns, no, w[_row(_NH, j)], cI, Ff, 0.0, 0.0, xi, a, mm,
                                          th, w[_row(_EX, j)])[0]
        t = ar * P
        w[_row(_ACC, j)] += t if (ns > 0.0 and no > 0.0) else 0.0


@nb.njit(cache=True, inline="always")
def _pass_other_add(mid, p, nx, ny, nz, ar, m, w):
    """Scalar pass: add ``A (n̂·ŝ)(n̂·ô) f_r`` of one facet of another model
    (:func:`~lightcurve.core.photometry.brdf_product_nb`) where it is lit and seen."""
    for j in range(m):
        sx = w[_row(_SB, j)]
        sy = w[_row(_SB + 1, j)]
        sz = w[_row(_SB + 2, j)]
        ox = w[_row(_SB + 3, j)]
        oy = w[_row(_SB + 4, j)]
        oz = w[_row(_SB + 5, j)]
        ns = nx * sx + ny * sy + nz * sz
        no = nx * ox + ny * oy + nz * oz
        if ns > 0.0 and no > 0.0:
            w[_row(_ACC, j)] += ar * brdf_product_nb(mid, p, nx, ny, nz, sx, sy, sz, ox, oy, oz)


@nb.njit(cache=True, inline="always")
def _pass_mag(m_out, b0, m, offset, w):
    """Scalar libm pass: ``m_out[i] = offset − 2.5 log10 Φ`` (+inf for Φ ≤ 0)."""
    for j in range(m):
        fl = w[_row(_ACC, j)]
        m_out[b0 + j] = offset - 2.5 * math.log10(fl) if fl > 0.0 else np.inf


@nb.njit(cache=True, parallel=True, error_model="numpy")
def bpf_predict_nb(Q, W, dt, mode, J, Ji, nsub, noise, Lnoise, zeta, s, o, normals, areas, ids,
                   params, offset, m_out, dq, dq_mode, work):
    """One fused bootstrap-PF prediction for every particle (in place on Q, W; fills m_out).

    mode 0: constant rate (controlled; the exact step ``exp(ω dt) ⊗ q``,
    :func:`~lightcurve.core.dynamics.const_rate_xyz`), 1: torque-free rigid body, ``nsub`` steps
    of the core's RK4 (:func:`~lightcurve.core.dynamics.rk4_step_xyz`; J, Ji (3,3) inertia
    kg m² and its inverse). ``noise`` (N,r) standard normals and ``Lnoise`` (6,r) a square root
    of the process-noise covariance: the sample ``Lnoise · noise[i]`` = [δθ (rad), δω (rad/s)]
    is applied after the deterministic step as ``q ← exp(δθ) ⊗ q``, ``ω ← ω + δω`` (``noise``
    (0,r): none). ``zeta`` (N,3) or (0,3): ACS attitude noise (rad) applied to the attitude
    *only for the predicted measurement* (controlled jitter model, Bernard eq. 7.8–7.11).
    ``m_out`` (N,) receives ``offset − 2.5 log10 Φ(q)`` (DESIGN.md magnitude equation; +inf
    where no light reaches the observer). With ``s[0]`` NaN no magnitude is computed
    (propagation only). The quaternions are renormalised; the facet sum uses the epoch's
    attitude-independent half vector and Fresnel factors (:func:`flux_invariants`). ``dq``
    (N,4) with ``dq_mode`` 1: the quaternions ``exp(ζ_i)`` formed here are also stored in
    ``dq``; 2: they are read from ``dq`` (formed by an earlier call for the same ζ; the same
    values, not formed again); 0: ``dq`` unused. ``work``: scratch of at least
    :func:`predict_work_size` doubles (a shorter one is replaced by a new buffer).

    Every per-particle formula is the one of :func:`predict_row` (the same operations in the
    same order, so the same bits as that row function and the CUDA kernel). The particles run
    in blocks of ``_BLOCK``: their rows are copied into scratch rows, the libm calls (sin/cos
    of the rotation steps, the Cook–Torrance exponentials, log10) run in scalar passes, and the
    rest in branch-free passes over the scratch rows, which the compiler vectorises across the
    block (the numpy error model — a division by zero gives inf/NaN instead of raising — is
    what lets it).
    """
    N = Q.shape[0]
    h = dt / max(nsub, 1)
    use_noise = noise.shape[0] == N
    use_zeta = zeta.shape[0] == N
    predict = not np.isnan(s[0])
    Jt = mat9(J)
    Kt = mat9(Ji)
    Fr = np.zeros(normals.shape[0])
    hI = (0.0, 0.0, 0.0)
    cI = -1.0
    if predict:
        hI, cI = flux_invariants(s, o, ids, params, Fr)
    use_dq = use_zeta and dq_mode != 0 and dq.shape[0] == N
    fill_dq = use_dq and dq_mode == 1
    read_dq = use_dq and dq_mode == 2
    form_dq = use_zeta and not read_dq and (predict or fill_dq)
    rate = dt != 0.0 and mode == 0
    sv = (s[0], s[1], s[2])
    ov = (o[0], o[1], o[2])
    nch = n_chunks(N)
    wk = work if work.shape[0] >= nch * _SLOTS * _BLOCK else np.empty(nch * _SLOTS * _BLOCK)
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        w = wk[c * _SLOTS * _BLOCK:(c + 1) * _SLOTS * _BLOCK]
        for b0 in range(lo, hi, _BLOCK):
            m = min(_BLOCK, hi - b0)
            # propagation
            if dt != 0.0 and mode != 0:
                for j in range(m):
                    i = b0 + j
                    Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3], W[i, 0], W[i, 1], W[i, 2] = _rk4_steps(
                        Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3], W[i, 0], W[i, 1], W[i, 2], h, nsub,
                        Jt, Kt)
            _copy_in(Q, b0, m, 4, w, _Q)
            if rate:
                _copy_in(W, b0, m, 3, w, _W)
                _norm3_into(w, _W, dt, _PHI, m)
                _sincos_half(w, _PHI, _SN, _CS, m)
            _pass_step(w, m, dt, rate, not use_noise)
            if use_noise:
                _pass_noise(noise, Lnoise, b0, m, w)
                _sincos_half(w, _NPHI, _NSN, _NCS, m)
                _pass_noise_apply(w, m)
            _pass_copy_out(Q, W, b0, m, use_noise, w)
            # the jitter's exp(ζ): formed (and kept in dq) or read from dq
            if form_dq:
                _copy_in(zeta, b0, m, 3, w, _Z)
                _norm3_into(w, _Z, 1.0, _ZPHI, m)
                _sincos_half(w, _ZPHI, _ZSN, _ZCS, m)
                _pass_jitter_q(w, m)
                if fill_dq:
                    _pass_copy_dq(dq, b0, m, w)
            elif read_dq and predict:
                _copy_in(dq, b0, m, 4, w, _D)
            if not predict:
                continue
            # the magnitude: body-frame ŝ, ô, ĥ, then the facet sum facet by facet
            _pass_body(m, use_zeta, sv, ov, hI, w)
            for f in range(normals.shape[0]):
                mid = ids[f]
                if mid < 0:
                    continue
                if mid == COOK_TORRANCE or mid == COOK_TORRANCE_THESIS:
                    _pass_ct_cosines(normals[f, 0], normals[f, 1], normals[f, 2], params[f, 2],
                                     m, w)
                    _pass_ct_exp(cI, m, w)
                    _pass_ct_add(areas[f], params[f, 0], params[f, 1], params[f, 2], Fr[f],
                                 mid == COOK_TORRANCE_THESIS, cI, m, w)
                else:
                    _pass_other_add(mid, params[f], normals[f, 0], normals[f, 1],
                                    normals[f, 2], areas[f], m, w)
            _pass_mag(m_out, b0, m, offset, w)


@nb.njit(cache=True, parallel=True)
def grp_times_rows(P, qref, a, f, Q):
    """``Q_i = normalise(grp2q(P_i) ⊗ qref)`` for the GRP rows P (N,3) (Bernard eq. 7.105,
    table 7.7's initial cloud): the values of
    :func:`lightcurve.core.rotations.from_grp_rel_nb`, computed in parallel into Q (N,4)."""
    for i in nb.prange(P.shape[0]):
        _grp_times(P[i, 0], P[i, 1], P[i, 2], a, f, qref, Q[i])


@nb.njit(cache=True, parallel=True)
def argmax_weights(w):
    """Index of the largest weight (the first one on ties, as ``numpy.argmax``)."""
    N = w.shape[0]
    nch = n_chunks(N)
    best = np.full(nch, -np.inf)
    arg = np.zeros(nch, dtype=np.int64)
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
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


@nb.njit(cache=True, inline="always")
def grp_weighted_mean_item(i, acc, args):
    """Adds ``w_i δp_i`` with δp_i the GRP of ``Q_i ⊗ qref⁻¹`` (Bernard eq. 7.100–7.102):
    :func:`grp_weighted_mean` ``(Q, qref, w, a, f)`` is ``Σ_i w_i δp_i`` (3,)."""
    Q, qref, w, a, f = args
    g0, g1, g2 = _grp_of_xyz(Q[i], qref, a, f)
    wi = w[i]
    return acc[0] + wi * g0, acc[1] + wi * g1, acc[2] + wi * g2


grp_weighted_mean = chunked_sum_kernel(grp_weighted_mean_item, 3)


@nb.njit(cache=True, inline="always")
def chart_row(i, Q, W, qref, a, f, X):
    """Row ``i`` of the chart of eq. 7.101: ``X[i, :3]`` = GRP of ``Q_i ⊗ qref⁻¹``,
    ``X[i, 3:6] = W_i``."""
    _grp_of(Q[i], qref, a, f, X[i, :3])
    for j in range(3):
        X[i, 3 + j] = W[i, j]


@nb.njit(cache=True, inline="always")
def chart_moment_row(i, Q, W, qref, a, f, w0, X, x):
    """:func:`chart_row` ``i`` and the row shifted for the one-pass moments of
    :func:`chart_stats`: ``x = [δp_i, ω_i − w0]`` (6,)."""
    chart_row(i, Q, W, qref, a, f, X)
    for j in range(3):
        x[j] = X[i, j]
        x[3 + j] = W[i, j] - w0[j]


@nb.njit(cache=True, parallel=True)
def chart_rows(Q, W, qref, a, f, X):
    """``X[i, :3]`` = GRP of ``Q_i ⊗ qref⁻¹``, ``X[i, 3:6] = W_i`` (the chart of eq. 7.101)."""
    N = Q.shape[0]
    for i in nb.prange(N):
        chart_row(i, Q, W, qref, a, f, X)


@nb.njit(cache=True, parallel=True)
def chart_stats(Q, W, w, qref, a, f, w0, X):
    """:func:`chart_rows` fused with the weighted moments of the rows ``x_i = [δp_i, ω_i]``:
    returns ``(mean (6,), cov (6,6))`` with ``mean = Σ w x``, ``cov = Σ w (x − mean)(x −
    mean)ᵀ`` (Bernard eq. 7.102–7.104; normalised weights). One pass, accumulated about the
    shift ``[0, 0, 0, w0]`` (w0 a rate near the mean, e.g. the heaviest particle's) so that
    the one-pass covariance keeps full precision. Each chunk sums its rows in order into
    scalar accumulators (registers: the chunk's 27 sums ``Σ w x_d`` and ``Σ w x_d x_e``,
    e ≤ d, written out); the chunks' sums are added in chunk order."""
    N = Q.shape[0]
    nch = n_chunks(N)
    S1 = np.zeros((nch, 6))
    S2 = np.zeros((nch, 6, 6))
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        s3 = 0.0
        s4 = 0.0
        s5 = 0.0
        c00 = c10 = c11 = c20 = c21 = c22 = c30 = 0.0
        c31 = c32 = c33 = c40 = c41 = c42 = c43 = 0.0
        c44 = c50 = c51 = c52 = c53 = c54 = c55 = 0.0
        for i in range(lo, hi):
            chart_row(i, Q, W, qref, a, f, X)
            x0 = X[i, 0]
            x1 = X[i, 1]
            x2 = X[i, 2]
            x3 = W[i, 0] - w0[0]
            x4 = W[i, 1] - w0[1]
            x5 = W[i, 2] - w0[2]
            wi = w[i]
            xd = wi * x0
            s0 += xd
            c00 += xd * x0
            xd = wi * x1
            s1 += xd
            c10 += xd * x0
            c11 += xd * x1
            xd = wi * x2
            s2 += xd
            c20 += xd * x0
            c21 += xd * x1
            c22 += xd * x2
            xd = wi * x3
            s3 += xd
            c30 += xd * x0
            c31 += xd * x1
            c32 += xd * x2
            c33 += xd * x3
            xd = wi * x4
            s4 += xd
            c40 += xd * x0
            c41 += xd * x1
            c42 += xd * x2
            c43 += xd * x3
            c44 += xd * x4
            xd = wi * x5
            s5 += xd
            c50 += xd * x0
            c51 += xd * x1
            c52 += xd * x2
            c53 += xd * x3
            c54 += xd * x4
            c55 += xd * x5
        S1[c, 0] = s0
        S1[c, 1] = s1
        S1[c, 2] = s2
        S1[c, 3] = s3
        S1[c, 4] = s4
        S1[c, 5] = s5
        S2[c, 0, 0] = c00
        S2[c, 1, 0] = c10
        S2[c, 1, 1] = c11
        S2[c, 2, 0] = c20
        S2[c, 2, 1] = c21
        S2[c, 2, 2] = c22
        S2[c, 3, 0] = c30
        S2[c, 3, 1] = c31
        S2[c, 3, 2] = c32
        S2[c, 3, 3] = c33
        S2[c, 4, 0] = c40
        S2[c, 4, 1] = c41
        S2[c, 4, 2] = c42
        S2[c, 4, 3] = c43
        S2[c, 4, 4] = c44
        S2[c, 5, 0] = c50
        S2[c, 5, 1] = c51
        S2[c, 5, 2] = c52
        S2[c, 5, 3] = c53
        S2[c, 5, 4] = c54
        S2[c, 5, 5] = c55
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
        roughen_chart_row(i, X, z, sig, ncols, qref, a, f, Q, W)


@nb.njit(cache=True, inline="always")
def roughen_chart_row(i, X, z, sig, ncols, qref, a, f, Q, W):
    """Row i of :func:`roughen_chart` (shared with the CUDA kernel)."""
    _grp_times(X[i, 0] + sig[0] * z[i, 0], X[i, 1] + sig[1] * z[i, 1],
               X[i, 2] + sig[2] * z[i, 2], a, f, qref, Q[i])
    if ncols == 6:
        for j in range(3):
            W[i, j] = X[i, 3 + j] + sig[3 + j] * z[i, 3 + j]


@nb.njit(cache=True, parallel=True)
def roughen_compose(Q, W, z, sig, a, f):
    """Bernard table 7.9 "Update state": ``c_i = σ ⊙ z_i``, ``q_i ← q(c_θ,i) ⊗ q_i`` (c_θ a GRP,
    eq. 7.108) and ``ω_i ← ω_i + c_ω,i`` (eq. 7.109); z (N, ≥6) standard normals (z (N,3):
    the attitude only)."""
    N = Q.shape[0]
    for i in nb.prange(N):
        roughen_compose_row(i, Q, W, z, sig, a, f)


@nb.njit(cache=True, inline="always")
def roughen_compose_row(i, Q, W, z, sig, a, f):
    """Row i of :func:`roughen_compose` (shared with the CUDA kernel)."""
    d0, d1, d2, d3 = grp2q_xyz(sig[0] * z[i, 0], sig[1] * z[i, 1], sig[2] * z[i, 2], a, f)
    e0, e1, e2, e3 = qmul_xyz(d0, d1, d2, d3, Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3])
    n = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
    Q[i, 0], Q[i, 1], Q[i, 2], Q[i, 3] = e0 / n, e1 / n, e2 / n, e3 / n
    if z.shape[1] >= 6:
        for j in range(3):
            W[i, j] += sig[3 + j] * z[i, 3 + j]


@nb.njit(cache=True, parallel=True)
def liu_west_attitude(X, eps, M, sa, c, qref, a, f, Q, W, E):
    """Liu & West (2001) kernel on the chart rows ``x_i = [δp, ω, e]`` of X (N, 6 + ne):
    ``x_i ← sa · x_i + c + M eps_i`` (``c = (1 − sa) x̄``, ``M = h L``), then
    ``Q_i = grp2q(δp_i) ⊗ qref``, ``W_i = ω_i``, ``E_i = e_i`` (E (N, ne))."""
    N = Q.shape[0]
    for i in nb.prange(N):
        liu_west_row(i, X, eps, M, sa, c, qref, a, f, Q, W, E)


@nb.njit(cache=True, inline="always")
def _lw(i, X, eps, M, sa, c, d):
    """Component d of the Liu–West move of row i: ``sa X[i,d] + c[d] + Σ_j M[d,j] eps[i,j]``."""
    acc = sa * X[i, d] + c[d]
    for j in range(eps.shape[1]):
        acc += M[d, j] * eps[i, j]
    return acc


@nb.njit(cache=True, inline="always")
def liu_west_row(i, X, eps, M, sa, c, qref, a, f, Q, W, E):
    """Row i of :func:`liu_west_attitude` (shared with the CUDA kernel)."""
    _grp_times(_lw(i, X, eps, M, sa, c, 0), _lw(i, X, eps, M, sa, c, 1),
               _lw(i, X, eps, M, sa, c, 2), a, f, qref, Q[i])
    for j in range(3):
        W[i, j] = _lw(i, X, eps, M, sa, c, 3 + j)
    for d in range(6, M.shape[0]):
        E[i, d - 6] = _lw(i, X, eps, M, sa, c, d)


@nb.njit(cache=True, parallel=True)
def min_abs_residual(mpred, y):
    """``min_i |y − m_i|`` over the finite predictions (+inf when none is finite)."""
    N = mpred.shape[0]
    nch = n_chunks(N)
    part = np.full(nch, np.inf)
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
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
    model ids. The facet sum is the core's (:func:`~lightcurve.core.photometry.facet_flux_nb`), so with
    ``p(Z[i])`` equal to the shape's values the two agree to round-off. +inf where no light
    reaches the observer. Parallel over chunks of particles; work buffers per chunk.
    """
    N = m_out.shape[0]
    F = normals.shape[0]
    P = params0.shape[1]
    qall = Q.shape[0] == N
    zall = Z.shape[0] == N
    use_zeta = zeta.shape[0] == N
    nch = n_chunks(N)
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        ar = np.empty(F)
        pr = np.empty((F, P))
        qm = np.empty(4)
        for i in range(lo, hi):
            iq = i if qall else 0
            iz = i if zall else 0
            fill_facet_arrays_nb(Z[iz], facet, kind_col, logit, areas0, params0, ar, pr)
            if use_zeta:
                d0, d1, d2, d3 = rotvec2q_xyz(zeta[i, 0], zeta[i, 1], zeta[i, 2])
                qm[0], qm[1], qm[2], qm[3] = qmul_xyz(d0, d1, d2, d3, Q[iq, 0], Q[iq, 1],
                                                      Q[iq, 2], Q[iq, 3])
            else:
                for j in range(4):
                    qm[j] = Q[iq, j]
            fl = facet_flux_nb(qm, s, o, normals, ar, ids, pr)
            m_out[i] = offset - 2.5 * math.log10(fl) if fl > 0.0 else np.inf


@nb.njit(cache=True)
def weighted_param_stats_nb(Z, w, logit):
    """Weighted mean and variance of unbounded states Z (N,D) and of their physical values.

    ``p = 1/(1+e^{−z})`` where ``logit[d]`` else ``e^{z}``; weights w (N,) sum to 1.
    Returns ``(z_mean, z_var, p_mean, p_var)``, each (D,).
    """
    D = Z.shape[1]
    zm = np.zeros(D)
    pm = np.zeros(D)
    z2 = np.zeros(D)
    p2 = np.zeros(D)
    _weighted_param_pass(Z, w, logit, False, zm, pm, zm, pm)
    _weighted_param_pass(Z, w, logit, True, zm, pm, z2, p2)
    return zm, z2, pm, p2


@nb.njit(cache=True, inline="always")
def _weighted_param_pass(Z, w, logit, second, zm, pm, zs, ps):
    """One pass of :func:`weighted_param_stats_nb` over the particles with non-zero weight:
    adds ``Σ w z`` to ``zs`` and ``Σ w p`` to ``ps`` (``second`` False), or the centred
    ``Σ w (z − zm)²`` and ``Σ w (p − pm)²`` (True)."""
    for i in range(Z.shape[0]):
        wi = w[i]
        if wi == 0.0:
            continue
        for d in range(Z.shape[1]):
            zz = Z[i, d]
            pp = from_unbounded_xyz(zz, logit[d])
            if second:
                zs[d] += wi * (zz - zm[d]) ** 2
                ps[d] += wi * (pp - pm[d]) ** 2
            else:
                zs[d] += wi * zz
                ps[d] += wi * pp


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
    nch = n_chunks(N)
    for c in nb.prange(nch):
        lo, hi = chunk_bounds(c, N, nch)
        ar = np.empty(F)
        pr = np.empty((F, P))
        for i in range(lo, hi):
            fill_facet_arrays_nb(Z[i], facet, kind_col, logit, areas0, params0, ar, pr)
            acc = 0.0
            for j in range(kmax + 1):
                wj = 1.0 if j < kmax else phi_last
                if wj == 0.0 or not np.isfinite(y[j]):
                    continue
                fl = facet_flux_nb(Qs[j], S[j], O[j], normals, ar, ids, pr)
                if not fl > 0.0:
                    acc = -np.inf
                    break
                r = (y[j] - (offs[j] - 2.5 * math.log10(fl))) / sig[j]
                acc += -0.5 * wj * r * r
            out[i] = acc


@nb.njit(cache=True)
def grp_compose(p, q, a, f):
    """``grp2q(p) ⊗ q`` (4,), not renormalised (Bernard eq. 7.105: the estimate from the mean
    GRP p (3,) about the reference q (4,)); the arithmetic of
    :func:`lightcurve.rotations.grp_to_quat` then :func:`lightcurve.rotations.quat_mult`,
    without their per-call array handling."""
    d0, d1, d2, d3 = grp2q_xyz(p[0], p[1], p[2], a, f)
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = qmul_xyz(d0, d1, d2, d3, q[0], q[1], q[2], q[3])
    return out
