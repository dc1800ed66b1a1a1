"""BRDFs, the facet-summed flux, the apparent magnitude and their analytic partials
(numba kernels on plain floats and float64 arrays, no validation).

Model ids (the packed parameter row has :data:`PARAM_COLUMNS` = 7 columns):

====  =========================  ==========================================================
 id    model                      parameter row
====  =========================  ==========================================================
 0     Lambert                    albedo
 1     Cook–Torrance              ξ, a (= F0), m (Beckmann rms slope)
 2     Phong                      Kd, Ks, n (exponent)
 3     Ashikhmin–Shirley          Rd, Rs, nu, nv, tx, ty, tz (unit tangent, body frame)
 4     Cook–Torrance (thesis)     ξ, a, m — diffuse term of Bernard eq. 5.8 as printed
 <0    not a kernel model         skipped here (evaluated in NumPy by the object layer)
====  =========================  ==========================================================

Directions are unit vectors in one frame (body axes): ``n̂`` facet normal, ``ŝ`` object→Sun,
``ô`` object→observer. The BRDF kernels return the *product* ``P = (n̂·ŝ)(n̂·ô) f_r`` for
``n̂·ŝ > 0, n̂·ô > 0`` (else 0) — the quantity the magnitude equation sums (Bernard eq. 5.4–5.6,
``A_vis`` of eq. 5.5) — which stays finite at grazing angles where ``f_r`` alone may not.

Magnitude (DESIGN.md, Bernard eq. 5.2–5.6 in consistent form):
``m = offset − 2.5 log10 Φ``, ``Φ = Σ_i A_i P_i`` (m² sr⁻¹),
``offset = m_sun + 5 log10 |r_obs| + 5 log10(|r_sun|/au)`` (+ an eclipse term).

Cook–Torrance (Bernard eq. 5.7–5.15, the physically consistent form of DESIGN.md):
``f_r = ξ a/π + (1−ξ) F D G / (4 (n̂·ŝ)(n̂·ô))``; Beckmann ``D = exp(−tan²γ/m²)/(π m² cos⁴γ)``,
``cos γ = n̂·ĥ`` (eq. 5.13–5.14); ``G = min(1, 2(n̂·ĥ)(n̂·ô)/c, 2(n̂·ĥ)(n̂·ŝ)/c)`` with
``c = ô·ĥ`` (eq. 5.15); Fresnel in the standard form
``F = ½ (g−c)²/(g+c)² [1 + (c(g+c)−1)²/(c(g−c)+1)²]``, ``g² = n² + c² − 1``,
``n = (1+√F0)/(1−√F0)`` (eq. 5.10–5.12), with ``a = F0``. Thesis slips not copied: eq. 5.10
prints ``c(g+c)+1`` as the second denominator; eq. 5.8 prints the diffuse term as
``ξ a (n̂·ŝ)/π`` — an extra cosine, since eq. 5.5 already carries it. That printed diffuse form
is model id 4 (``thesis=True`` in :func:`cook_torrance_xyz`), kept selectable for
reproducing the thesis.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .rotations import qrot_xyz_nb

__all__ = [
    "LAMBERT", "COOK_TORRANCE", "PHONG", "ASHIKHMIN_SHIRLEY", "COOK_TORRANCE_THESIS",
    "ANALYTIC_IDS", "PARAM_COLUMNS", "fresnel_xyz", "beckmann_exponent", "beckmann_xyz",
    "beckmann_exp_xyz", "cook_torrance_xyz", "cook_torrance_fresnel_xyz",
    "cook_torrance_fresnel_exp_xyz", "facet_sum_xyz", "facet_sum_fresnel_xyz",
    "brdf_product_nb", "brdf_value_kernel", "brightness_kernel", "facet_products_kernel",
    "facet_flux_nb", "mag_kernel_nb", "flux_partials_nb", "partials_many_nb",
    "magnitude_partials_q_nb", "nchunks_nb",
]

LAMBERT = 0
COOK_TORRANCE = 1
PHONG = 2
ASHIKHMIN_SHIRLEY = 3
COOK_TORRANCE_THESIS = 4
ANALYTIC_IDS = (LAMBERT, COOK_TORRANCE, PHONG, COOK_TORRANCE_THESIS)
"""Model ids with analytic partials in :func:`flux_partials_nb`."""
PARAM_COLUMNS = 7
"""Width of a packed BRDF parameter row."""

_INV_PI = 1.0 / math.pi


@nb.njit(cache=True, inline="always")
def fresnel_xyz(c, f0):
    """Cook–Torrance Fresnel factor and its derivatives → ``(F, ∂F/∂c, ∂F/∂F0)``.

    ``F = ½ A² (1 + B²)``, ``A = (g−c)/(g+c)``, ``B = (c(g+c) − 1)/(c(g−c) + 1)``,
    ``g = √(n² + c² − 1)``, ``n = (1+√F0)/(1−√F0)`` (Bernard eq. 5.10–5.12, standard second
    denominator). ``c = ô·ĥ``; ∂F/∂c is the total derivative (``g' = c/g``), ∂F/∂F0 goes
    through ``g(n(F0))``. Scalars.
    """
    u = math.sqrt(f0)
    nr = (1.0 + u) / (1.0 - u)
    g = math.sqrt(nr * nr + c * c - 1.0)
    A = (g - c) / (g + c)
    N1 = c * (g + c) - 1.0
    N2 = c * (g - c) + 1.0
    B = N1 / N2
    F = 0.5 * A * A * (1.0 + B * B)
    gp = c / g
    dA_dc = (2.0 * c * gp - 2.0 * g) / (g + c) ** 2
    dB_dc = ((g + c * gp + 2.0 * c) * N2 - N1 * (g + c * gp - 2.0 * c)) / N2 ** 2
    dF_dc = A * dA_dc * (1.0 + B * B) + A * A * B * dB_dc
    dA_dg = 2.0 * c / (g + c) ** 2
    dB_dg = c * (2.0 - 2.0 * c * c) / N2 ** 2
    dF_dg = A * dA_dg * (1.0 + B * B) + A * A * B * dB_dg
    dnr_df0 = 1.0 / (u * (1.0 - u) ** 2)
    return F, dF_dc, dF_dg * (nr / g) * dnr_df0


@nb.njit(cache=True, inline="always")
def beckmann_exponent(nh, m):
    """Exponent ``−tan²γ/m² = (cos²γ − 1)/(cos²γ m²)`` of the Beckmann distribution,
    ``cos γ = n̂·ĥ`` (Bernard eq. 5.13)."""
    nh2 = nh * nh
    return (nh2 - 1.0) / (nh2 * m * m)


@nb.njit(cache=True, inline="always")
def beckmann_xyz(nh, m):
    """Beckmann distribution ``D = exp(−tan²γ/m²)/(π m² cos⁴γ)``, ``cos γ = n̂·ĥ > 0``
    (Bernard eq. 5.13–5.14) and its derivatives → ``(D, ∂D/∂(n̂·ĥ), ∂D/∂m)``.

    ``∂D/∂cos γ = D (2/(m² cos³γ) − 4/cos γ)``, ``∂D/∂m = D (2 tan²γ/m³ − 2/m)``.
    """
    return beckmann_exp_xyz(nh, m, math.exp(beckmann_exponent(nh, m)))


@nb.njit(cache=True, inline="always")
def beckmann_exp_xyz(nh, m, e):
    """:func:`beckmann_xyz` with its exponential given: ``e = exp(beckmann_exponent(nh, m))``
    (for callers that evaluate the exponentials of many attitudes in a separate pass)."""
    nh2 = nh * nh
    D = e / (math.pi * m * m * nh2 * nh2)
    tan2 = (1.0 - nh2) / nh2
    return D, D * (2.0 / (m * m * nh ** 3) - 4.0 / nh), D * (2.0 * tan2 / m ** 3 - 2.0 / m)


@nb.njit(cache=True, inline="always")
def cook_torrance_xyz(ns, no, nh, c, xi, a, m, thesis):
    """Cook–Torrance product ``P = (n̂·ŝ)(n̂·ô) f_r`` and its partial derivatives (module
    docstring; Bernard eq. 5.7–5.15) → 8-tuple
    ``(P, ∂P/∂ns, ∂P/∂no, ∂P/∂nh, ∂P/∂c, ∂P/∂ξ, ∂P/∂a, ∂P/∂m)``.

    ``ns = n̂·ŝ > 0``, ``no = n̂·ô > 0``, ``nh = n̂·ĥ``, ``c = ô·ĥ``; ``ξ`` diffuse fraction,
    ``a = F0``, ``m`` Beckmann slope; ``thesis`` selects eq. 5.8's printed diffuse form.
    :func:`fresnel_xyz` then :func:`cook_torrance_fresnel_xyz`.
    """
    # no shortcut at ξ = 1 (Table 9.2's fully diffuse −Z): the (1 − ξ) weight zeroes the
    # specular value, but ∂P/∂ξ = diffuse − FDG/4 needs F, D, G there, and the value stays
    # affine in ξ across the bound (finite differences of ξ agree with ∂P/∂ξ)
    if nh <= 0.0 or c <= 0.0:
        return cook_torrance_fresnel_xyz(ns, no, nh, c, 0.0, 0.0, 0.0, xi, a, m, thesis)
    F, dF_dc, dF_df0 = fresnel_xyz(c, a)
    return cook_torrance_fresnel_xyz(ns, no, nh, c, F, dF_dc, dF_df0, xi, a, m, thesis)


@nb.njit(cache=True, inline="always")
def cook_torrance_fresnel_xyz(ns, no, nh, c, F, dF_dc, dF_df0, xi, a, m, thesis):
    """:func:`cook_torrance_xyz` with the Fresnel factor given: ``F = F(c, a)``, ``∂F/∂c``,
    ``∂F/∂F0`` from :func:`fresnel_xyz` (rotation invariant — ``c = ô·ĥ = |ŝ+ô|/2`` does not
    depend on the attitude — so a caller evaluating many attitudes at one epoch computes them
    once per facet material; pass zeros for the derivatives it does not use).

    ``P = ξ a/π ns no + (1−ξ)/4 F D G`` (physical form), or ``ξ a/π ns² no + …`` with
    ``thesis`` (eq. 5.8 as printed). The specular term is zero for ``nh ≤ 0`` or ``c ≤ 0``
    (and its value, not its ξ-derivative, for ``ξ = 1``). At the kinks of ``min(…)`` in G the derivative of the active branch is returned.
    Callers that use only ``P`` pay nothing for the derivatives (inlined, the unused arithmetic
    is removed by the compiler).
    """
    e = math.exp(beckmann_exponent(nh, m)) if (nh > 0.0 and c > 0.0) else 0.0
    return cook_torrance_fresnel_exp_xyz(ns, no, nh, c, F, dF_dc, dF_df0, xi, a, m, thesis, e)


@nb.njit(cache=True, inline="always")
def cook_torrance_fresnel_exp_xyz(ns, no, nh, c, F, dF_dc, dF_df0, xi, a, m, thesis, e):
    """:func:`cook_torrance_fresnel_xyz` with the Beckmann exponential given:
    ``e = exp(beckmann_exponent(nh, m))`` where ``nh > 0`` and ``c > 0`` (unused elsewhere), so
    that a caller can evaluate the value of many attitudes with the exponentials in a separate
    pass and the rest vectorised."""
    kd = xi * a * _INV_PI
    if thesis:
        diff = kd * ns * ns * no
        d_ns = 2.0 * kd * ns * no
        d_no = kd * ns * ns
        d_xi = a * _INV_PI * ns * ns * no
        d_a = xi * _INV_PI * ns * ns * no
    else:
        diff = kd * ns * no
        d_ns = kd * no
        d_no = kd * ns
        d_xi = a * _INV_PI * ns * no
        d_a = xi * _INV_PI * ns * no
    if nh <= 0.0 or c <= 0.0:
        return diff, d_ns, d_no, 0.0, 0.0, d_xi, d_a, 0.0
    D, dD_dnh, dD_dm = beckmann_exp_xyz(nh, m, e)
    G = 1.0
    dG_dns = 0.0
    dG_dno = 0.0
    dG_dnh = 0.0
    dG_dc = 0.0
    g1 = 2.0 * nh * no / c
    g2 = 2.0 * nh * ns / c
    if g1 < G:
        G = g1
    if g2 < G:
        G = g2
    if g1 < 1.0 and g1 <= g2:
        dG_dnh = 2.0 * no / c
        dG_dno = 2.0 * nh / c
        dG_dc = -g1 / c
    elif g2 < 1.0:
        dG_dnh = 2.0 * ns / c
        dG_dns = 2.0 * nh / c
        dG_dc = -g2 / c
    ks = (1.0 - xi) * 0.25
    P = diff + ks * F * D * G
    return (P, d_ns + ks * F * D * dG_dns, d_no + ks * F * D * dG_dno,
            ks * F * (dD_dnh * G + D * dG_dnh), ks * D * (dF_dc * G + F * dG_dc),
            d_xi - 0.25 * F * D * G, d_a + ks * D * G * dF_df0, ks * F * G * dD_dm)


@nb.njit(cache=True, inline="always")
def _half_vector(sx, sy, sz, ox, oy, oz, nx, ny, nz):
    """``(n̂·ĥ, ô·ĥ, |ŝ+ô|)`` with ``ĥ = (ŝ+ô)/|ŝ+ô|``; ``(0, 0, 0)`` when ŝ = −ô."""
    hx = sx + ox
    hy = sy + oy
    hz = sz + oz
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if hn <= 0.0:
        return 0.0, 0.0, 0.0
    return (nx * hx + ny * hy + nz * hz) / hn, (ox * hx + oy * hy + oz * hz) / hn, hn


@nb.njit(cache=True)
def brdf_product_nb(model, p, nx, ny, nz, sx, sy, sz, ox, oy, oz):
    """``(n̂·ŝ)(n̂·ô) f_r`` (sr⁻¹) for model id ``model`` with packed row ``p`` (module table).

    Returns 0 when the facet faces away from the Sun or the observer, or for an unknown /
    non-kernel model id (< 0). Lambert ``f_r = albedo/π``; Phong
    ``f_r = Kd/π + Ks (n+2)/(2π) (r̂·ô)ⁿ`` with ``r̂ = 2(n̂·ŝ)n̂ − ŝ`` (lobe zero for r̂·ô < 0);
    Cook–Torrance :func:`cook_torrance_xyz`; Ashikhmin & Shirley (2000), J. Graphics Tools
    5(2): ``ρ_s`` with its ``√((nu+1)(nv+1))/(8π)`` normalisation and Schlick Fresnel, and the
    energy-conserving diffuse term ``28 Rd/(23π) (1−Rs)(1−(1−ns/2)⁵)(1−(1−no/2)⁵)``.
    """
    ns = nx * sx + ny * sy + nz * sz
    no = nx * ox + ny * oy + nz * oz
    if ns <= 0.0 or no <= 0.0:
        return 0.0
    if model == LAMBERT:
        return p[0] * _INV_PI * ns * no
    if model == COOK_TORRANCE or model == COOK_TORRANCE_THESIS:
        nh, c, _hn = _half_vector(sx, sy, sz, ox, oy, oz, nx, ny, nz)
        return cook_torrance_xyz(ns, no, nh, c, p[0], p[1], p[2], model == COOK_TORRANCE_THESIS)[0]
    if model == PHONG:
        ro = 2.0 * ns * no - (sx * ox + sy * oy + sz * oz)
        f = p[0] * _INV_PI
        if ro > 0.0:
            f += p[1] * (p[2] + 2.0) / (2.0 * math.pi) * ro ** p[2]
        return f * ns * no
    if model == ASHIKHMIN_SHIRLEY:
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

    Where n̂·ŝ ≤ 0 or n̂·ô ≤ 0 the value is 0 (the BRDF is not defined there).
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


_NO_FRESNEL = np.empty(0)


@nb.njit(cache=True, inline="always")
def facet_sum_fresnel_xyz(sx, sy, sz, ox, oy, oz, hx, hy, hz, c, Fr, normals, areas, ids, params):
    """``Φ = Σ_i A_i (n̂_i·ŝ)⁺(n̂_i·ô)⁺ f_r,i`` (m² sr⁻¹; Bernard eq. 5.4–5.6) for body-frame
    ŝ, ô; facets with a model id < 0 are skipped.

    ``Fr`` (F,): the Cook–Torrance facets' Fresnel factors precomputed for the epoch (rotation
    invariant, :func:`cook_torrance_fresnel_xyz`) with the body-frame half vector ``ĥ`` and
    ``c = ô·ĥ``; those facets then go through :func:`cook_torrance_fresnel_xyz`. An empty
    ``Fr`` (:func:`facet_sum_xyz`): every facet through :func:`brdf_product_nb`."""
    pre = Fr.shape[0] > 0
    acc = 0.0
    for f in range(normals.shape[0]):
        mid = ids[f]
        if mid < 0:
            continue
        nx = normals[f, 0]
        ny = normals[f, 1]
        nz = normals[f, 2]
        ns = nx * sx + ny * sy + nz * sz
        if ns <= 0.0:
            continue
        no = nx * ox + ny * oy + nz * oz
        if no <= 0.0:
            continue
        if pre and (mid == COOK_TORRANCE or mid == COOK_TORRANCE_THESIS):
            nh = nx * hx + ny * hy + nz * hz
            p = params[f]
            acc += areas[f] * cook_torrance_fresnel_xyz(
                ns, no, nh, c, Fr[f], 0.0, 0.0, p[0], p[1], p[2],
                mid == COOK_TORRANCE_THESIS)[0]
        else:
            acc += areas[f] * brdf_product_nb(mid, params[f], nx, ny, nz, sx, sy, sz, ox, oy, oz)
    return acc


@nb.njit(cache=True, inline="always")
def facet_sum_xyz(sx, sy, sz, ox, oy, oz, normals, areas, ids, params):
    """``Φ = Σ_i A_i (n̂_i·ŝ)⁺(n̂_i·ô)⁺ f_r,i`` (m² sr⁻¹; Bernard eq. 5.4–5.6) for body-frame
    ŝ, ô; facets with a model id < 0 are skipped (:func:`facet_sum_fresnel_xyz` without
    precomputed Fresnel factors)."""
    return facet_sum_fresnel_xyz(sx, sy, sz, ox, oy, oz, 0.0, 0.0, 0.0, 0.0, _NO_FRESNEL,
                                 normals, areas, ids, params)


@nb.njit(cache=True, parallel=True)
def brightness_kernel(normals, areas, model_ids, params, s_body, o_body):
    """Facet-summed flux factor ``Σ_i A_i max(n̂_i·ŝ,0) max(n̂_i·ô,0) f_r,i`` (m² sr⁻¹).

    normals (F,3) body frame; areas (F,) m²; model_ids (F,) (< 0 skipped); params (F,P);
    s_body, o_body (N,S,3) unit object→Sun / object→observer in body axes. Returns (N,S),
    parallel over the N·S epoch-state pairs.
    """
    N = s_body.shape[0]
    S = s_body.shape[1]
    out = np.zeros((N, S))
    for k in nb.prange(N * S):
        i = k // S
        j = k - i * S
        out[i, j] = facet_sum_xyz(s_body[i, j, 0], s_body[i, j, 1], s_body[i, j, 2],
                                  o_body[i, j, 0], o_body[i, j, 1], o_body[i, j, 2],
                                  normals, areas, model_ids, params)
    return out


@nb.njit(cache=True, parallel=True)
def facet_products_kernel(normals, areas, model_ids, params, s_body, o_body):
    """Per-facet products ``A_i (n̂·ŝ)(n̂·ô) f_r,i`` for M direction pairs (M,3),(M,3) → (M,F)."""
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


@nb.njit(cache=True, inline="always")
def facet_flux_nb(q, s, o, normals, areas, ids, params):
    """Φ (m² sr⁻¹) of ONE attitude ``q`` (4,) (inertial→body) for unit ECI directions s, o (3,):
    ŝ, ô rotated into body axes by ``A(q)`` (Bernard eq. 3.16), then :func:`facet_sum_xyz`."""
    sx, sy, sz = qrot_xyz_nb(q[0], q[1], q[2], q[3], s[0], s[1], s[2])
    ox, oy, oz = qrot_xyz_nb(q[0], q[1], q[2], q[3], o[0], o[1], o[2])
    return facet_sum_xyz(sx, sy, sz, ox, oy, oz, normals, areas, ids, params)


@nb.njit(cache=True)
def nchunks_nb(N):
    """Number of work chunks for N particles (≥ 1; about 64 particles or more per chunk)."""
    c = N // 64
    if c < 1:
        c = 1
    if c > 256:
        c = 256
    return c


@nb.njit(cache=True, parallel=True)
def mag_kernel_nb(Q, s, o, normals, areas, ids, params, offset):
    """Apparent magnitudes (S,) of attitudes Q (S,4) at one epoch (Bernard eq. 5.2–5.6 in the
    consistent form of the module docstring).

    ``m = offset − 2.5 log10 Φ(q)``; s, o (3,) unit ECI object→Sun / object→observer; +inf
    where no light is reflected to the observer. Parallel over chunks of attitudes.
    """
    S = Q.shape[0]
    out = np.empty(S)
    nch = nchunks_nb(S)
    for c in nb.prange(nch):
        lo = c * S // nch
        hi = (c + 1) * S // nch
        for i in range(lo, hi):
            fl = facet_flux_nb(Q[i], s, o, normals, areas, ids, params)
            out[i] = offset - 2.5 * math.log10(fl) if fl > 0.0 else np.inf
    return out


@nb.njit(cache=True)
def flux_partials_nb(sx, sy, sz, ox, oy, oz, normals, areas, ids, params, P, dxi, da, dmm):
    """Flux Φ and its raw partials at one body-frame geometry, one pass over the facets.

    sx…oz: unit ŝ, ô in body axes; normals (F,3), areas (F,) m², ids (F,) (only ids in
    :data:`ANALYTIC_IDS` — the caller checks), params (F,7). Written in place (F,): ``P`` =
    ``(n̂·ŝ)(n̂·ô) f_r`` per facet (sr⁻¹, without the area); ``dxi, da, dmm`` = ∂P/∂ξ, ∂P/∂a,
    ∂P/∂m of Cook–Torrance facets (0 where not lit and visible; NaN for other BRDFs).
    Returns ``(Φ, ∂Φ/∂δθ_x, _y, _z)``, ``Φ = Σ A_i P_i`` and
    ``∂Φ/∂δθ = Σ A_i (∇_s P_i × ŝ + ∇_o P_i × ô)``: the body-frame error rotation δθ
    (``q = δq(δθ) ⊗ q̂``) moves body directions as ``ŝ → ŝ + ŝ × δθ`` (Bernard eq. 8.19–8.33
    in the consistent form; the sign of eq. 6.56 corrected). Cook–Torrance gradients by the
    chain rule through ``n̂·ŝ, n̂·ô, n̂·ĥ, ô·ĥ`` with ``∇(n̂·ĥ) = (n̂ − (n̂·ĥ)ĥ)/|ŝ+ô|`` and
    ``∇(ô·ĥ) = ĥ/2`` (the same in ŝ and ô).
    """
    F = normals.shape[0]
    flux = 0.0
    tx = 0.0
    ty = 0.0
    tz = 0.0
    wx = sx + ox
    wy = sy + oy
    wz = sz + oz
    wn = math.sqrt(wx * wx + wy * wy + wz * wz)
    wd = wn if wn > 0.0 else 1.0
    hx = wx / wd
    hy = wy / wd
    hz = wz / wd
    so = sx * ox + sy * oy + sz * oz
    for f in range(F):
        mid = ids[f]
        nx = normals[f, 0]
        ny = normals[f, 1]
        nz = normals[f, 2]
        ns = nx * sx + ny * sy + nz * sz
        no = nx * ox + ny * oy + nz * oz
        ct = mid == COOK_TORRANCE or mid == COOK_TORRANCE_THESIS
        if ct:
            dxi[f] = 0.0
            da[f] = 0.0
            dmm[f] = 0.0
        else:
            dxi[f] = np.nan
            da[f] = np.nan
            dmm[f] = np.nan
        if ns <= 0.0 or no <= 0.0:
            P[f] = 0.0
            continue
        p = params[f]
        # gradients ∇_s P and ∇_o P (body axes)
        if mid == LAMBERT:
            Pf = brdf_product_nb(mid, p, nx, ny, nz, sx, sy, sz, ox, oy, oz)
            rho = p[0] / math.pi
            gsx = rho * no * nx
            gsy = rho * no * ny
            gsz = rho * no * nz
            gox = rho * ns * nx
            goy = rho * ns * ny
            goz = rho * ns * nz
        elif mid == PHONG:
            Pf = brdf_product_nb(mid, p, nx, ny, nz, sx, sy, sz, ox, oy, oz)
            Kd = p[0]
            Ks = p[1]
            ex = p[2]
            ro = 2.0 * ns * no - so
            lobe = 0.0
            dlobe = 0.0
            if ro > 0.0:
                lobe = Ks * (ex + 2.0) / (2.0 * math.pi) * ro ** ex
                dlobe = Ks * (ex + 2.0) / (2.0 * math.pi) * ex * ro ** (ex - 1.0)
            fr = Kd / math.pi + lobe
            k2 = ns * no * dlobe
            # ∇_s ro = 2(n̂·ô) n̂ − ô ; ∇_o ro = 2(n̂·ŝ) n̂ − ŝ
            gsx = fr * no * nx + k2 * (2.0 * no * nx - ox)
            gsy = fr * no * ny + k2 * (2.0 * no * ny - oy)
            gsz = fr * no * nz + k2 * (2.0 * no * nz - oz)
            gox = fr * ns * nx + k2 * (2.0 * ns * nx - sx)
            goy = fr * ns * ny + k2 * (2.0 * ns * ny - sy)
            goz = fr * ns * nz + k2 * (2.0 * ns * nz - sz)
        else:  # Cook–Torrance (either diffuse form)
            nh, c, _hn = _half_vector(sx, sy, sz, ox, oy, oz, nx, ny, nz)
            Pf, d_ns, d_no, d_nh, d_c, d_xi, d_a, d_m = cook_torrance_xyz(
                ns, no, nh, c, p[0], p[1], p[2], mid == COOK_TORRANCE_THESIS)
            dxi[f] = d_xi
            da[f] = d_a
            dmm[f] = d_m
            nhh = nx * hx + ny * hy + nz * hz
            gnx = d_nh * (nx - nhh * hx) / wd + d_c * 0.5 * hx
            gny = d_nh * (ny - nhh * hy) / wd + d_c * 0.5 * hy
            gnz = d_nh * (nz - nhh * hz) / wd + d_c * 0.5 * hz
            gsx = d_ns * nx + gnx
            gsy = d_ns * ny + gny
            gsz = d_ns * nz + gnz
            gox = d_no * nx + gnx
            goy = d_no * ny + gny
            goz = d_no * nz + gnz
        P[f] = Pf
        A = areas[f]
        flux += A * Pf
        # ∇_s P × ŝ + ∇_o P × ô
        tx += A * ((gsy * sz - gsz * sy) + (goy * oz - goz * oy))
        ty += A * ((gsz * sx - gsx * sz) + (goz * ox - gox * oz))
        tz += A * ((gsx * sy - gsy * sx) + (gox * oy - goy * ox))
    return flux, tx, ty, tz


@nb.njit(cache=True)
def partials_many_nb(sb, ob, normals, areas, ids, params):
    """:func:`flux_partials_nb` for M body-frame geometries (M,3),(M,3) → flux (M,), P, dxi,
    da, dmm (M,F), ∂Φ/∂δθ (M,3). Serial."""
    M = sb.shape[0]
    F = normals.shape[0]
    flux = np.empty(M)
    P = np.empty((M, F))
    dxi = np.empty((M, F))
    da = np.empty((M, F))
    dmm = np.empty((M, F))
    dth = np.empty((M, 3))
    for k in range(M):
        fl, tx, ty, tz = flux_partials_nb(sb[k, 0], sb[k, 1], sb[k, 2], ob[k, 0], ob[k, 1],
                                          ob[k, 2], normals, areas, ids, params, P[k], dxi[k],
                                          da[k], dmm[k])
        flux[k] = fl
        dth[k, 0] = tx
        dth[k, 1] = ty
        dth[k, 2] = tz
    return flux, P, dxi, da, dmm, dth


@nb.njit(cache=True)
def magnitude_partials_q_nb(q, s, o, normals, areas, ids, params, offset, dm_dA, dm_dxi,
                            dm_da, dm_dm):
    """Magnitude and every partial of ONE attitude in one pass (the Kalman filters' path).

    q (4,) inertial→body quaternion; s, o (3,) unit ECI object→Sun / object→observer;
    normals, areas, ids (in :data:`ANALYTIC_IDS`), params the shape's kernel arrays; offset
    (mag) so that ``m = offset − 2.5 log10 Φ``. ``∂m/∂p = −2.5/ln 10 · (∂Φ/∂p)/Φ``. Writes
    ∂m/∂A (mag m⁻²), ∂m/∂ξ, ∂m/∂a, ∂m/∂m (F,) (NaN for non-Cook–Torrance facets) and returns
    ``(m, ∂m/∂δθ_x, _y, _z)`` (mag, mag rad⁻¹); m = +inf and NaN partials where Φ = 0.
    """
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    sx, sy, sz = qrot_xyz_nb(q0, q1, q2, q3, s[0], s[1], s[2])
    ox, oy, oz = qrot_xyz_nb(q0, q1, q2, q3, o[0], o[1], o[2])
    F = normals.shape[0]
    P = np.empty(F)
    flux, dx, dy, dz = flux_partials_nb(sx, sy, sz, ox, oy, oz, normals, areas, ids, params,
                                        P, dm_dxi, dm_da, dm_dm)
    if flux > 0.0:
        K = -2.5 / math.log(10.0) / flux
        m = offset - 2.5 * math.log10(flux)
    else:
        K = np.nan
        m = np.inf
    for f in range(F):
        dm_dA[f] = K * P[f]
        dm_dxi[f] *= K * areas[f]
        dm_da[f] *= K * areas[f]
        dm_dm[f] *= K * areas[f]
    return m, K * dx, K * dy, K * dz
