"""Numba kernels of the built-in BRDFs and of the facet-summed brightness.

Plain float64 arrays only; the object layer (:mod:`.magnitude`, :class:`.facets.Shape`) packs
shapes into these arrays. Model ids (column layout of the packed parameter row, width
:data:`lightcurve.photometry.brdf.PARAM_COLUMNS` = 7):

====  ===================  ==============================================================
 id    model                params row
====  ===================  ==============================================================
 0     Lambert              albedo
 1     Cook–Torrance        xi, a (= F0), m (Beckmann rms slope)
 2     Phong                Kd, Ks, n (exponent)
 3     Ashikhmin–Shirley    Rd, Rs, nu, nv, tx, ty, tz (unit tangent, body frame)
 <0    not a kernel model   skipped here (evaluated in numpy by the object layer)
====  ===================  ==============================================================

All directions are unit vectors in one frame (body axes in practice): ``n`` facet normal,
``s`` object→Sun, ``o`` object→observer. Every function returns the *product*
``P = (n·s)(n·o) f_r`` for ``n·s > 0``, ``n·o > 0`` and 0 otherwise; this is the quantity the
magnitude equation sums (Bernard eq. 5.2–5.6 in the consistent form of DESIGN.md) and it is
finite at grazing angles where ``f_r`` alone may not be.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = [
    "LAMBERT", "COOK_TORRANCE", "PHONG", "ASHIKHMIN_SHIRLEY",
    "brdf_product_nb", "brdf_value_kernel", "brightness_kernel", "facet_products_kernel",
    "ct_product_fresnel", "fresnel_ct",
]

LAMBERT = 0
COOK_TORRANCE = 1
PHONG = 2
ASHIKHMIN_SHIRLEY = 3

_INV_PI = 1.0 / math.pi


@nb.njit(cache=True, inline="always")
def fresnel_ct(c, f0):
    """Cook–Torrance Fresnel factor (standard form), c = ô·ĥ, f0 = normal-incidence reflectance.

    F = ½ (g−c)²/(g+c)² [1 + (c(g+c)−1)²/(c(g−c)+1)²], g² = n² + c² − 1,
    n = (1+√F0)/(1−√F0)  (the standard form prescribed by DESIGN.md).
    """
    sf = math.sqrt(f0)
    nr = (1.0 + sf) / (1.0 - sf)
    g = math.sqrt(nr * nr + c * c - 1.0)
    A = (g - c) / (g + c)
    B = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * A * A * (1.0 + B * B)


@nb.njit(cache=True, inline="always")
def ct_product_fresnel(ns, no, nh, c, F, xi, a, m):
    """(n·s)(n·o) f_r for Cook–Torrance with its Fresnel factor ``F`` given.

    f_r = ξ a/π + (1−ξ) F D G / (4 (n·s)(n·o)); the diffuse term is ξ a/π, *without* the
    extra (n̂·ŝ) factor of the thesis's eq. 5.8 (a slip: the cosine is already in the
    magnitude equation). D is the normalised Beckmann distribution
    D = exp(−tan²α/m²)/(π m² cos⁴α), cos α = n̂·ĥ. G = min(1, 2(n̂·ĥ)(n̂·ô)/(ô·ĥ),
    2(n̂·ĥ)(n̂·ŝ)/(ô·ĥ)) — the thesis's eq. 5.10 writes a different second denominator; we
    use ô·ĥ in both (= ŝ·ĥ by construction of ĥ). ``c = ô·ĥ`` and ``F = F(c, F0)``
    (:func:`fresnel_ct`) do not change with the attitude (both vectors rotate together), so
    a caller evaluating many attitudes at one geometry computes F once.
    """
    diff = xi * a * _INV_PI * ns * no
    if xi >= 1.0 or nh <= 0.0 or c <= 0.0:
        return diff
    nh2 = nh * nh
    D = math.exp((nh2 - 1.0) / (nh2 * m * m)) / (math.pi * m * m * nh2 * nh2)
    G = 1.0
    g1 = 2.0 * nh * no / c
    g2 = 2.0 * nh * ns / c
    if g1 < G:
        G = g1
    if g2 < G:
        G = g2
    return diff + (1.0 - xi) * 0.25 * F * D * G


@nb.njit(cache=True, inline="always")
def _ct_product(ns, no, nh, c, xi, a, m):
    """(n·s)(n·o) f_r for Cook–Torrance (:func:`ct_product_fresnel` with F = F(c, a))."""
    if xi >= 1.0 or nh <= 0.0 or c <= 0.0:
        return xi * a * _INV_PI * ns * no
    return ct_product_fresnel(ns, no, nh, c, fresnel_ct(c, a), xi, a, m)


@nb.njit(cache=True)
def brdf_product_nb(model, p, nx, ny, nz, sx, sy, sz, ox, oy, oz):
    """Scalar kernel: (n·s)(n·o) f_r for model id ``model`` with packed row ``p``.

    Returns 0 when the facet faces away from the Sun or the observer, or for an unknown /
    non-kernel model id (< 0).
    """
    ns = nx * sx + ny * sy + nz * sz
    no = nx * ox + ny * oy + nz * oz
    if ns <= 0.0 or no <= 0.0:
        return 0.0
    if model == LAMBERT:
        return p[0] * _INV_PI * ns * no
    if model == COOK_TORRANCE:
        hx = sx + ox
        hy = sy + oy
        hz = sz + oz
        hn = math.sqrt(hx * hx + hy * hy + hz * hz)
        if hn <= 0.0:
            return p[0] * p[1] * _INV_PI * ns * no
        nh = (nx * hx + ny * hy + nz * hz) / hn
        c = (ox * hx + oy * hy + oz * hz) / hn
        return _ct_product(ns, no, nh, c, p[0], p[1], p[2])
    if model == PHONG:
        # r̂ = mirror of ŝ about n̂ = 2(n̂·ŝ)n̂ − ŝ; specular lobe zero when r̂·ô < 0.
        ro = 2.0 * ns * no - (sx * ox + sy * oy + sz * oz)
        f = p[0] * _INV_PI
        if ro > 0.0:
            f += p[1] * (p[2] + 2.0) / (2.0 * math.pi) * ro ** p[2]
        return f * ns * no
    if model == ASHIKHMIN_SHIRLEY:
        # Ashikhmin & Shirley (2000), "An anisotropic Phong BRDF model", J. Graphics Tools
        # 5(2): eq. for rho_s (with its sqrt((nu+1)(nv+1))/(8π) normalisation and Schlick
        # Fresnel) and the energy-conserving diffuse term 28 Rd/(23π) (1−Rs)(...)(...).
        Rd = p[0]
        Rs = p[1]
        nu = p[2]
        nv = p[3]
        hx = sx + ox
        hy = sy + oy
        hz = sz + oz
        hn = math.sqrt(hx * hx + hy * hy + hz * hz)
        t1 = 1.0 - 0.5 * ns
        t2 = 1.0 - 0.5 * no
        rd = 28.0 * Rd / (23.0 * math.pi) * (1.0 - Rs) * (1.0 - t1 ** 5) * (1.0 - t2 ** 5)
        if hn <= 0.0:
            return rd * ns * no
        hx /= hn
        hy /= hn
        hz /= hn
        nh = nx * hx + ny * hy + nz * hz
        kh = ox * hx + oy * hy + oz * hz
        # tangent u (packed), bitangent v = n × u
        ux = p[4]
        uy = p[5]
        uz = p[6]
        vx = ny * uz - nz * uy
        vy = nz * ux - nx * uz
        vz = nx * uy - ny * ux
        hu = hx * ux + hy * uy + hz * uz
        hv = hx * vx + hy * vy + hz * vz
        den = 1.0 - nh * nh
        if den > 1e-14:
            expo = (nu * hu * hu + nv * hv * hv) / den
        else:
            expo = 0.0  # ĥ = n̂: (n̂·ĥ)^expo = 1 whatever the (bounded) exponent
        mx = ns if ns > no else no
        fres = Rs + (1.0 - Rs) * (1.0 - kh) ** 5
        rs = math.sqrt((nu + 1.0) * (nv + 1.0)) / (8.0 * math.pi) * nh ** expo / (kh * mx) * fres
        return (rs + rd) * ns * no
    return 0.0


@nb.njit(cache=True, parallel=True)
def brdf_value_kernel(model_ids, params, n, s, o):
    """f_r (sr⁻¹) for M independent triples; rows of n, s, o (M,3), params (M,P), ids (M,).

    Where n·s ≤ 0 or n·o ≤ 0 the value is 0 (the BRDF is not defined there).
    """
    M = n.shape[0]
    out = np.zeros(M)
    for k in nb.prange(M):
        ns = n[k, 0] * s[k, 0] + n[k, 1] * s[k, 1] + n[k, 2] * s[k, 2]
        no = n[k, 0] * o[k, 0] + n[k, 1] * o[k, 1] + n[k, 2] * o[k, 2]
        if ns <= 0.0 or no <= 0.0:
            continue
        P = brdf_product_nb(model_ids[k], params[k], n[k, 0], n[k, 1], n[k, 2],
                            s[k, 0], s[k, 1], s[k, 2], o[k, 0], o[k, 1], o[k, 2])
        out[k] = P / (ns * no)
    return out


@nb.njit(cache=True, parallel=True)
def brightness_kernel(normals, areas, model_ids, params, s_body, o_body):
    """Facet-summed flux factor Σ_i A_i max(n̂_i·ŝ,0) max(n̂_i·ô,0) f_r,i  [m² sr⁻¹].

    Parameters
    ----------
    normals : (F,3) float64   unit facet normals, body frame
    areas : (F,) float64      facet areas, m²
    model_ids : (F,) int64    kernel model id per facet (< 0: skipped, handled elsewhere)
    params : (F,P) float64    packed BRDF parameters per facet
    s_body : (N,S,3) float64  unit object→Sun direction in body axes per epoch and state
    o_body : (N,S,3) float64  unit object→observer direction in body axes

    Returns
    -------
    (N,S) float64, parallel (prange) over the N·S epoch-state pairs.
    """
    N = s_body.shape[0]
    S = s_body.shape[1]
    F = normals.shape[0]
    out = np.zeros((N, S))
    for k in nb.prange(N * S):
        i = k // S
        j = k - i * S
        sx = s_body[i, j, 0]
        sy = s_body[i, j, 1]
        sz = s_body[i, j, 2]
        ox = o_body[i, j, 0]
        oy = o_body[i, j, 1]
        oz = o_body[i, j, 2]
        acc = 0.0
        for f in range(F):
            mid = model_ids[f]
            if mid < 0:
                continue
            nx = normals[f, 0]
            ny = normals[f, 1]
            nz = normals[f, 2]
            if nx * sx + ny * sy + nz * sz <= 0.0 or nx * ox + ny * oy + nz * oz <= 0.0:
                continue
            acc += areas[f] * brdf_product_nb(mid, params[f], nx, ny, nz, sx, sy, sz, ox, oy, oz)
        out[i, j] = acc
    return out


@nb.njit(cache=True, parallel=True)
def facet_products_kernel(normals, areas, model_ids, params, s_body, o_body):
    """Per-facet products A_i (n̂·ŝ)(n̂·ô) f_r,i for M direction pairs: (M,3),(M,3) -> (M,F).

    Used by the partial-derivative layer and by tests; same conventions as
    :func:`brightness_kernel`.
    """
    M = s_body.shape[0]
    F = normals.shape[0]
    out = np.zeros((M, F))
    for k in nb.prange(M):
        for f in range(F):
            mid = model_ids[f]
            if mid < 0:
                continue
            out[k, f] = areas[f] * brdf_product_nb(
                mid, params[f], normals[f, 0], normals[f, 1], normals[f, 2],
                s_body[k, 0], s_body[k, 1], s_body[k, 2], o_body[k, 0], o_body[k, 1], o_body[k, 2])
    return out
