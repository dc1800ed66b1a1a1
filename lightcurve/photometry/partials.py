"""Analytic partial derivatives of the apparent magnitude (Bernard eq. 8.19–8.33, consistent form).

With Φ = Σ_i A_i P_i, P_i = max(n̂_i·ŝ,0) max(n̂_i·ô,0) f_r,i (body frame) and
m = m_sun − 2.5 log10(Φ/|r_obs|²) + 5 log10(|r_sun|/au), every partial is

    ∂m/∂p = −2.5/ln(10) · (∂Φ/∂p) / Φ.

For a Cook–Torrance facet the product needs no division by the cosines:

    P = ξ a/π (n̂·ŝ)(n̂·ô) + (1−ξ)/4 · F(c) D(n̂·ĥ) G,   c = ô·ĥ,

so ∂P/∂ξ = a/π (n̂·ŝ)(n̂·ô) − F D G/4, ∂P/∂a = ξ/π (n̂·ŝ)(n̂·ô) + (1−ξ)/4 D G ∂F/∂F0 (a = F0
enters both the diffuse albedo and the Fresnel index n = (1+√F0)/(1−√F0)),
∂P/∂m = (1−ξ)/4 F G ∂D/∂m with ∂D/∂m = D (2 tan²α/m³ − 2/m). These replace the thesis's
eq. 8.19–8.33, which differentiate its inconsistent form (eq. 5.8's extra n̂·ŝ); note also
that the thesis's eq. 6.56 drops a minus sign — the sign here follows from m = −2.5 log10 Φ.

Attitude: the error rotation vector δθ (body frame) acts as q = δq(δθ) ⊗ q̂ with
δq ≈ [1, δθ/2], so A(q) ≈ (I − [δθ×]) A(q̂) and a body-frame direction moves as
ŝ_b → ŝ_b + ŝ_b × δθ. Hence ∂Φ/∂δθ = Σ_i A_i (∇_s P_i × ŝ + ∇_o P_i × ô), with the
gradients ∇_s, ∇_o of P in body axes. Analytic for Lambert, Cook–Torrance and Phong facets;
for other BRDFs (Ashikhmin–Shirley, tabulated, user models) the attitude partial of those
facets is a central finite difference (step 1e-6 rad) — stated here, not hidden.

Partials are not defined where Φ = 0 (m = +inf); they are NaN there. At the kinks of
max(·,0) and of G's min(…) the one-sided derivative of the active branch is returned.

Two implementations of the same algebra: the vectorised NumPy one (any BRDF; the reference)
and numba kernels that make one pass over the facets per geometry from plain arrays
(:func:`flux_partials_nb`; :func:`magnitude_partials_q_nb` for one attitude, the Kalman
filters' per-epoch call) for shapes whose facets are all Lambert, Cook–Torrance or Phong
(:func:`kernel_capable`). :func:`magnitude_partials` picks the kernel when it can
(``backend="auto"``); the two agree to rounding (tests/filters/
test_filters_model3_speed_equivalence.py, ≤ 1e-10 relative).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from ..rotations import qrot_xyz_nb, quat_rotate, rotvec_to_quat
from .facets import Shape
from .kernels import COOK_TORRANCE, LAMBERT, PHONG, brdf_product_nb, facet_products_kernel
from .magnitude import SUN_MAG_V, body_directions, magnitude_from_flux

__all__ = ["MagnitudePartials", "magnitude_partials", "facet_products", "flux_partials_nb",
           "magnitude_partials_q_nb", "kernel_capable"]

_LN10 = np.log(10.0)


@dataclass
class MagnitudePartials:
    """Magnitude and its partials for N epochs (or N·S flattened epoch-states reshaped back).

    Attributes (leading shape L = (N,) or (N,S))
    ----------
    m : L                magnitude
    flux : L             Φ = Σ A_i P_i, m² sr⁻¹
    dm_dA : L+(F,)       ∂m/∂A_i, mag m⁻²
    dm_dxi, dm_da, dm_dm : L+(F,)  Cook–Torrance ∂m/∂ξ_i, ∂m/∂a_i (a = F0), ∂m/∂m_i
                         (NaN for facets with another BRDF)
    dm_dtheta : L+(3,)   ∂m/∂δθ, mag rad⁻¹, δθ a body-frame error rotation vector
    """

    m: np.ndarray
    flux: np.ndarray
    dm_dA: np.ndarray
    dm_dxi: np.ndarray
    dm_da: np.ndarray
    dm_dm: np.ndarray
    dm_dtheta: np.ndarray


def facet_products(shape: Shape, s_body, o_body) -> np.ndarray:
    """P_i = max(n̂·ŝ,0) max(n̂·ô,0) f_r,i per facet (without the area), (M,3),(M,3) -> (M,F)."""
    sb = np.ascontiguousarray(s_body, float).reshape(-1, 3)
    ob = np.ascontiguousarray(o_body, float).reshape(-1, 3)
    n, _, ids, p = shape.kernel_arrays()
    out = facet_products_kernel(n, np.ones(shape.n_facets), ids, p, sb, ob)
    for brdf, idx in shape.numpy_groups:
        nf = shape.normals_body[idx]
        ns = sb @ nf.T
        no = ob @ nf.T
        params = {k: shape.param_table[k][idx] for k in brdf.param_names}
        f = brdf.evaluate(nf[None], sb[:, None, :], ob[:, None, :], params)
        out[:, idx] = np.where((ns > 0) & (no > 0), ns * no * f, 0.0)
    return out


def _fresnel_and_derivs(c, f0):
    """F(c; F0), ∂F/∂c and ∂F/∂F0 of the standard Cook–Torrance Fresnel term (arrays; the
    numba kernels call :func:`_fresnel_derivs_nb` on scalars — one implementation)."""
    c, f0 = np.broadcast_arrays(np.asarray(c, dtype=float), np.asarray(f0, dtype=float))
    return _fresnel_derivs_nb(np.ascontiguousarray(c), np.ascontiguousarray(f0))


# --------------------------------------------------------------------------------------------
# numba kernels: the same partials in one pass over the facets, from plain arrays
# --------------------------------------------------------------------------------------------

#: BRDF model ids with analytic partials in the kernels below (others: NumPy path + FD)
_ANALYTIC_IDS = (LAMBERT, COOK_TORRANCE, PHONG)


@nb.njit(cache=True, inline="always")
def _fresnel_derivs_nb(c, f0):
    """``(F, ∂F/∂c, ∂F/∂F0)`` of the standard Cook–Torrance Fresnel term (DESIGN.md:
    ``F = ½ (g−c)²/(g+c)² [1 + (c(g+c)−1)²/(c(g−c)+1)²]``, ``g² = n² + c² − 1``,
    ``n = (1+√F0)/(1−√F0)``); ``c`` = ô·ĥ. Scalars or equal-shape arrays; ∂F/∂c is the total
    derivative (g depends on c: g' = c/g), ∂F/∂F0 goes through g(n(F0))."""
    u = np.sqrt(f0)
    nr = (1.0 + u) / (1.0 - u)
    g = np.sqrt(nr * nr + c * c - 1.0)
    A = (g - c) / (g + c)
    N1 = c * g + c * c - 1.0
    N2 = c * g - c * c + 1.0
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


@nb.njit(cache=True)
def flux_partials_nb(sx, sy, sz, ox, oy, oz, normals, areas, ids, params, P, dxi, da, dmm):
    """Flux Φ and its raw partials at one body-frame geometry, one pass over the facets.

    sx…oz : unit object→Sun ŝ and object→observer ô in body axes; normals (F,3), areas (F,)
    m², ids (F,) BRDF ids (only LAMBERT, COOK_TORRANCE, PHONG — the caller checks), params
    (F,7) packed rows. Outputs written in place (F,): ``P`` = (n̂·ŝ)(n̂·ô) f_r per facet
    (without the area, sr⁻¹), ``dxi, da, dmm`` = ∂P/∂ξ, ∂P/∂a, ∂P/∂m of Cook–Torrance facets
    (0 where not lit and visible; NaN for other BRDFs). Returns ``(Φ, ∂Φ/∂δθ_x, _y, _z)``
    with Φ = Σ A_i P_i (m² sr⁻¹) and ∂Φ/∂δθ = Σ A_i (∇_s P_i × ŝ + ∇_o P_i × ô) (module
    docstring; δθ body-frame error rotation, rad). The algebra is that of the NumPy
    :func:`_partials_block` (the test oracle), facet by facet.
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
    c = 0.5 * wn                                   # ô·ĥ = |ŝ+ô|/2
    so = sx * ox + sy * oy + sz * oz
    for f in range(F):
        mid = ids[f]
        nx = normals[f, 0]
        ny = normals[f, 1]
        nz = normals[f, 2]
        ns = nx * sx + ny * sy + nz * sz
        no = nx * ox + ny * oy + nz * oz
        if mid == COOK_TORRANCE:
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
        Pf = brdf_product_nb(mid, p, nx, ny, nz, sx, sy, sz, ox, oy, oz)
        P[f] = Pf
        # gradients ∇_s P and ∇_o P (body axes)
        if mid == LAMBERT:
            rho = p[0] / math.pi
            gsx = rho * no * nx
            gsy = rho * no * ny
            gsz = rho * no * nz
            gox = rho * ns * nx
            goy = rho * ns * ny
            goz = rho * ns * nz
        elif mid == PHONG:
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
        else:  # COOK_TORRANCE
            xi = p[0]
            a = p[1]
            m = p[2]
            nh = nx * hx + ny * hy + nz * hz
            dif = xi * a / math.pi
            gsx = dif * no * nx
            gsy = dif * no * ny
            gsz = dif * no * nz
            gox = dif * ns * nx
            goy = dif * ns * ny
            goz = dif * ns * nz
            cos2 = ns * no
            dxi[f] = a / math.pi * cos2
            da[f] = xi / math.pi * cos2
            # specular quantities also at ξ = 1 (Table 9.2's −Z): the value has no specular
            # part there, but ∂P/∂ξ = a(n̂·ŝ)(n̂·ô)/π − FDG/4 still needs FDG
            if nh > 0.0 and c > 0.0:
                nh2 = nh * nh
                D = math.exp((nh2 - 1.0) / (nh2 * m * m)) / (math.pi * m * m * nh2 * nh2)
                dD_dnh = D * (2.0 / (m * m * nh ** 3) - 4.0 / nh)
                tan2 = (1.0 - nh2) / nh2
                dD_dm = D * (2.0 * tan2 / m ** 3 - 2.0 / m)
                g1 = 2.0 * nh * no / c
                g2 = 2.0 * nh * ns / c
                G = min(1.0, min(g1, g2))
                Fr, dF_dc, dF_df0 = _fresnel_derivs_nb(c, a)
                # ∇(n̂·ĥ) = (n̂ − (n̂·ĥ) ĥ)/|ŝ+ô| and ∇c = ĥ/2 (the same in ŝ and ô)
                gnx = (nx - nh * hx) / wd
                gny = (ny - nh * hy) / wd
                gnz = (nz - nh * hz) / wd
                gcx = 0.5 * hx
                gcy = 0.5 * hy
                gcz = 0.5 * hz
                # ∇G of the active branch of min(1, g1, g2)
                dsx = dsy = dsz = dox = doy = doz = 0.0
                if g1 < 1.0 and g1 <= g2:
                    k1 = 2.0 * nh * no / (c * c)
                    dsx = 2.0 * (no * gnx) / c - k1 * gcx
                    dsy = 2.0 * (no * gny) / c - k1 * gcy
                    dsz = 2.0 * (no * gnz) / c - k1 * gcz
                    dox = 2.0 * (no * gnx + nh * nx) / c - k1 * gcx
                    doy = 2.0 * (no * gny + nh * ny) / c - k1 * gcy
                    doz = 2.0 * (no * gnz + nh * nz) / c - k1 * gcz
                elif g2 < 1.0:
                    k1 = 2.0 * nh * ns / (c * c)
                    dsx = 2.0 * (ns * gnx + nh * nx) / c - k1 * gcx
                    dsy = 2.0 * (ns * gny + nh * ny) / c - k1 * gcy
                    dsz = 2.0 * (ns * gnz + nh * nz) / c - k1 * gcz
                    dox = 2.0 * (ns * gnx) / c - k1 * gcx
                    doy = 2.0 * (ns * gny) / c - k1 * gcy
                    doz = 2.0 * (ns * gnz) / c - k1 * gcz
                ks = (1.0 - xi) / 4.0
                a1 = ks * (dF_dc * D * G)
                a2 = ks * (Fr * dD_dnh * G)
                a3 = ks * Fr * D
                cx = a1 * gcx + a2 * gnx
                cy = a1 * gcy + a2 * gny
                cz = a1 * gcz + a2 * gnz
                gsx += cx + a3 * dsx
                gsy += cy + a3 * dsy
                gsz += cz + a3 * dsz
                gox += cx + a3 * dox
                goy += cy + a3 * doy
                goz += cz + a3 * doz
                dxi[f] -= Fr * D * G / 4.0
                da[f] += ks * D * G * dF_df0
                dmm[f] = ks * Fr * G * dD_dm
        A = areas[f]
        flux += A * Pf
        # ∇_s P × ŝ + ∇_o P × ô
        tx += A * ((gsy * sz - gsz * sy) + (goy * oz - goz * oy))
        ty += A * ((gsz * sx - gsx * sz) + (goz * ox - gox * oz))
        tz += A * ((gsx * sy - gsy * sx) + (gox * oy - goy * ox))
    return flux, tx, ty, tz


@nb.njit(cache=True)
def _partials_many_nb(sb, ob, normals, areas, ids, params):
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

    q (4,) inertial→body quaternion (scalar first, passive); s, o (3,) unit object→Sun and
    object→observer directions in ECI; normals, areas, ids, params the shape's
    ``kernel_arrays()`` (ids in LAMBERT, COOK_TORRANCE, PHONG only); offset (mag) =
    m_sun + 5 log10|r_obs| + 5 log10(|r_sun|/au) (+ eclipse term), so
    ``m = offset − 2.5 log10 Φ``. Writes ∂m/∂A (mag m⁻²), ∂m/∂ξ, ∂m/∂a, ∂m/∂m (F,) into the
    given arrays (NaN for non-Cook–Torrance facets) and returns ``(m, ∂m/∂δθ_x, _y, _z)``
    (mag, mag rad⁻¹); m = +inf and NaN partials where Φ = 0.
    """
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    # ŝ, ô in body axes: A(q) v, the passive inertial→body rotation
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


def kernel_capable(ids) -> bool:
    """True when every facet's BRDF id has analytic partials in the numba kernels
    (Lambert, Cook–Torrance, Phong); other shapes use the NumPy path."""
    ids = np.asarray(ids)
    return bool(np.all(np.isin(ids, _ANALYTIC_IDS)))


_CHUNK_ELEMENTS = 2_000_000  # epoch-states × facets per block (bounds temporary memory)


def magnitude_partials(shape: Shape, q, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m,
                       sun_mag: float = SUN_MAG_V, *, backend: str = "auto") -> MagnitudePartials:
    """Magnitude and analytic partials (module docstring); same inputs as
    :func:`~lightcurve.photometry.magnitude.apparent_magnitude` (q (N,4) or (N,S,4)).

    ``backend``: ``"numba"`` — one pass over the facets per geometry
    (:func:`flux_partials_nb`; every facet Lambert, Cook–Torrance or Phong, else ValueError);
    ``"numpy"`` — the vectorised NumPy algebra (any BRDF; the reference the kernel is tested
    against to 1e-12); ``"auto"`` (default) — numba when the shape allows it. Both give the
    same numbers to rounding.

    Large requests are processed in blocks of epochs so that temporaries stay below about
    a few hundred MB (epochs·states·facets ≤ 2e6 per block); results are concatenated.
    """
    if backend not in ("auto", "numba", "numpy"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'numpy', got {backend!r}")
    use_nb = kernel_capable(shape.model_ids)
    if backend == "numba" and not use_nb:
        raise ValueError("backend='numba' needs every facet Lambert, Cook-Torrance or Phong")
    block = _partials_block_nb if (use_nb and backend != "numpy") else _partials_block
    qa = np.asarray(q, float)
    if qa.ndim == 1:
        qa = qa[None, :]
    N = qa.shape[0]
    per_epoch = (qa.shape[1] if qa.ndim == 3 else 1) * shape.n_facets
    step = max(1, _CHUNK_ELEMENTS // max(per_epoch, 1))
    if N <= step:
        return block(shape, qa, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m, sun_mag)
    s = np.broadcast_to(np.asarray(sun_dir_eci, float).reshape(-1, 3), (N, 3))
    o = np.broadcast_to(np.asarray(obs_dir_eci, float).reshape(-1, 3), (N, 3))
    ro = np.broadcast_to(np.asarray(range_obs_m, float), (N,))
    rs = np.broadcast_to(np.asarray(range_sun_m, float), (N,))
    parts = [block(shape, qa[i:i + step], s[i:i + step], o[i:i + step], ro[i:i + step],
                             rs[i:i + step], sun_mag) for i in range(0, N, step)]
    return MagnitudePartials(*(np.concatenate([getattr(p, f) for p in parts])
                               for f in MagnitudePartials.__dataclass_fields__))


def _partials_block_nb(shape, qa, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m, sun_mag):
    """The numba form of :func:`_partials_block` (same outputs; kernel-capable shapes)."""
    sb3, ob3 = body_directions(qa, sun_dir_eci, obs_dir_eci)          # (N,S,3)
    N, S = sb3.shape[:2]
    sb = np.ascontiguousarray(sb3.reshape(-1, 3))
    ob = np.ascontiguousarray(ob3.reshape(-1, 3))
    F = shape.n_facets
    n, A, ids, p = shape.kernel_arrays()
    flux, P, dxi, da, dmm, dth = _partials_many_nb(
        sb, ob, np.ascontiguousarray(n, dtype=float), np.ascontiguousarray(A, dtype=float),
        np.ascontiguousarray(ids, dtype=np.int64), np.ascontiguousarray(p, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        K = np.where(flux > 0, -2.5 / _LN10 / flux, np.nan)[:, None]
    mag = magnitude_from_flux(flux.reshape(N, S), range_obs_m, range_sun_m, sun_mag)
    lead = (N,) if qa.ndim <= 2 else (N, S)
    return MagnitudePartials(
        m=mag.reshape(lead), flux=flux.reshape(lead), dm_dA=(K * P).reshape(lead + (F,)),
        dm_dxi=(K * A * dxi).reshape(lead + (F,)), dm_da=(K * A * da).reshape(lead + (F,)),
        dm_dm=(K * A * dmm).reshape(lead + (F,)), dm_dtheta=(K * dth).reshape(lead + (3,)))


def _partials_block(shape, qa, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m, sun_mag):
    """NumPy implementation (any BRDF; FD attitude partials for BRDFs without analytic ones)."""
    sb3, ob3 = body_directions(qa, sun_dir_eci, obs_dir_eci)          # (N,S,3)
    N, S = sb3.shape[:2]
    sb = sb3.reshape(-1, 3)
    ob = ob3.reshape(-1, 3)
    M = sb.shape[0]
    F = shape.n_facets
    nrm = shape.normals_body
    A = shape.areas_m2
    P = facet_products(shape, sb, ob)                                   # (M,F)
    flux = P @ A
    with np.errstate(divide="ignore", invalid="ignore"):
        K = np.where(flux > 0, -2.5 / _LN10 / flux, np.nan)            # (M,)

    ns = sb @ nrm.T
    no = ob @ nrm.T
    vis = (ns > 0) & (no > 0)
    w = sb + ob
    wn = np.linalg.norm(w, axis=1)                                      # (M,)
    h = w / np.where(wn > 0, wn, 1.0)[:, None]
    nh = h @ nrm.T                                                      # (M,F)
    c = 0.5 * wn[:, None] * np.ones((1, F))                             # ô·ĥ = |ŝ+ô|/2

    gs = np.zeros((M, F, 3))                                            # ∇_s P
    go = np.zeros((M, F, 3))                                            # ∇_o P
    dxi = np.full((M, F), np.nan)
    da = np.full((M, F), np.nan)
    dmm = np.full((M, F), np.nan)
    ids = shape.model_ids
    nvec = nrm[None, :, :]
    # ∇ of n̂·ĥ and c (identical in s and o)
    grad_nh = (nvec - nh[..., None] * h[:, None, :]) / np.where(wn > 0, wn, 1.0)[:, None, None]
    grad_c = np.broadcast_to(0.5 * h[:, None, :], (M, F, 3))

    lam = ids == LAMBERT
    if np.any(lam):
        rho = shape.params[lam, 0] / np.pi
        gs[:, lam] = (rho * no[:, lam])[..., None] * nvec[:, lam]
        go[:, lam] = (rho * ns[:, lam])[..., None] * nvec[:, lam]

    pho = ids == PHONG
    if np.any(pho):
        Kd, Ks, ex = (shape.params[pho, j] for j in range(3))
        nsp, nop = ns[:, pho], no[:, pho]
        so = np.einsum("mk,mk->m", sb, ob)[:, None]
        ro = 2.0 * nsp * nop - so
        pos = ro > 0
        rop = np.where(pos, ro, 1.0)
        lobe = np.where(pos, Ks * (ex + 2.0) / (2.0 * np.pi) * rop**ex, 0.0)
        dlobe = np.where(pos, Ks * (ex + 2.0) / (2.0 * np.pi) * ex * rop ** (ex - 1.0), 0.0)
        fr = Kd / np.pi + lobe
        nv = nvec[:, pho]
        # ∇_s ro = 2(n̂·ô) n̂ − ô ; ∇_o ro = 2(n̂·ŝ) n̂ − ŝ
        dro_s = 2.0 * nop[..., None] * nv - ob[:, None, :]
        dro_o = 2.0 * nsp[..., None] * nv - sb[:, None, :]
        gs[:, pho] = (fr * nop)[..., None] * nv + (nsp * nop * dlobe)[..., None] * dro_s
        go[:, pho] = (fr * nsp)[..., None] * nv + (nsp * nop * dlobe)[..., None] * dro_o

    ct = ids == COOK_TORRANCE
    if np.any(ct):
        xi, a, m = (shape.params[ct, j] for j in range(3))
        nsc, noc, nhc, cc = ns[:, ct], no[:, ct], nh[:, ct], c[:, ct]
        nv = nvec[:, ct]
        spec = (nhc > 0) & (cc > 0)   # also at ξ = 1: ∂P/∂ξ needs FDG there
        nhs = np.where(spec, nhc, 1.0)
        cs = np.where(spec, cc, 1.0)
        nh2 = nhs * nhs
        D = np.exp((nh2 - 1.0) / (nh2 * m * m)) / (np.pi * m * m * nh2 * nh2)
        dD_dnh = D * (2.0 / (m * m * nhs**3) - 4.0 / nhs)
        tan2 = (1.0 - nh2) / nh2
        dD_dm = D * (2.0 * tan2 / m**3 - 2.0 / m)
        g1 = 2.0 * nhs * noc / cs
        g2 = 2.0 * nhs * nsc / cs
        G = np.minimum(1.0, np.minimum(g1, g2))
        Fr, dF_dc, dF_df0 = _fresnel_and_derivs(cs, a)
        zero = ~spec
        D = np.where(zero, 0.0, D)
        dD_dnh = np.where(zero, 0.0, dD_dnh)
        dD_dm = np.where(zero, 0.0, dD_dm)
        gnh = grad_nh[:, ct]
        gcs = grad_c[:, ct]
        # ∇G of the active branch
        use1 = (g1 < 1.0) & (g1 <= g2)
        use2 = (g2 < 1.0) & ~use1
        dG_s = np.where(use1[..., None], 2.0 * (noc[..., None] * gnh) / cs[..., None]
                        - (2.0 * nhs * noc / cs**2)[..., None] * gcs, 0.0)
        dG_s = np.where(use2[..., None], 2.0 * (nsc[..., None] * gnh + nhs[..., None] * nv) / cs[..., None]
                        - (2.0 * nhs * nsc / cs**2)[..., None] * gcs, dG_s)
        dG_o = np.where(use1[..., None], 2.0 * (noc[..., None] * gnh + nhs[..., None] * nv) / cs[..., None]
                        - (2.0 * nhs * noc / cs**2)[..., None] * gcs, 0.0)
        dG_o = np.where(use2[..., None], 2.0 * (nsc[..., None] * gnh) / cs[..., None]
                        - (2.0 * nhs * nsc / cs**2)[..., None] * gcs, dG_o)
        kspec = (1.0 - xi) / 4.0
        common = (kspec * (dF_dc * D * G))[..., None] * gcs + (kspec * (Fr * dD_dnh * G))[..., None] * gnh
        gs[:, ct] = (xi * a / np.pi * noc)[..., None] * nv + common + (kspec * Fr * D)[..., None] * dG_s
        go[:, ct] = (xi * a / np.pi * nsc)[..., None] * nv + common + (kspec * Fr * D)[..., None] * dG_o
        cos2 = nsc * noc
        dxi[:, ct] = np.where(vis[:, ct], a / np.pi * cos2 - Fr * D * G / 4.0, 0.0)
        da[:, ct] = np.where(vis[:, ct], xi / np.pi * cos2 + kspec * D * G * dF_df0, 0.0)
        dmm[:, ct] = np.where(vis[:, ct], kspec * Fr * G * dD_dm, 0.0)

    gs = np.where(vis[..., None], gs, 0.0)
    go = np.where(vis[..., None], go, 0.0)
    dflux_dth = np.einsum("f,mfk->mk", A, np.cross(gs, sb[:, None, :]) + np.cross(go, ob[:, None, :]))

    other = ~(lam | pho | ct)
    if np.any(other):  # finite differences for the remaining BRDFs (documented above)
        hstep = 1e-6
        idx = np.flatnonzero(other)
        sub = _subshape(shape, idx)
        for k in range(3):
            e = np.zeros(3)
            e[k] = hstep
            dqp = rotvec_to_quat(e)
            dqm = rotvec_to_quat(-e)
            fp = facet_products(sub, quat_rotate(dqp, sb), quat_rotate(dqp, ob)) @ A[idx]
            fm = facet_products(sub, quat_rotate(dqm, sb), quat_rotate(dqm, ob)) @ A[idx]
            dflux_dth[:, k] += (fp - fm) / (2.0 * hstep)

    mag = magnitude_from_flux(flux.reshape(N, S), range_obs_m, range_sun_m, sun_mag)
    lead = (N,) if qa.ndim <= 2 else (N, S)
    Kc = K[:, None]
    out = MagnitudePartials(
        m=mag.reshape(lead),
        flux=flux.reshape(lead),
        dm_dA=(Kc * P).reshape(lead + (F,)),
        dm_dxi=(Kc * A * dxi).reshape(lead + (F,)),
        dm_da=(Kc * A * da).reshape(lead + (F,)),
        dm_dm=(Kc * A * dmm).reshape(lead + (F,)),
        dm_dtheta=(Kc * dflux_dth).reshape(lead + (3,)),
    )
    return out


def _subshape(shape: Shape, idx) -> Shape:
    return Shape(shape.name, shape.areas_m2[idx], shape.normals_body[idx], shape.centers_body_m[idx],
                 [shape.materials[i] for i in idx], shape.mass_kg, shape.inertia_kg_m2,
                 convex=shape.convex, tangents_body=shape.tangents_body[idx])

