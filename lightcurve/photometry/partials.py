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

The algebra is done once, by the numba kernels of :mod:`lightcurve.core.photometry`
(:func:`~lightcurve.core.photometry.flux_partials_nb`, one pass over the facets per geometry;
:func:`~lightcurve.core.photometry.magnitude_partials_q_nb` for one attitude, the Kalman filters'
per-epoch call). :func:`magnitude_partials` packs a shape for them; facets with other BRDFs
are summed by :func:`facet_products` and get the finite-difference attitude partial.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.photometry import ANALYTIC_IDS, facet_products_kernel, partials_many_nb
from ..rotations import quat_rotate, rotvec_to_quat
from .facets import Shape
from .magnitude import SUN_MAG_V, body_directions, magnitude_from_flux

__all__ = ["MagnitudePartials", "magnitude_partials", "facet_products", "kernel_capable"]

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


def kernel_capable(ids) -> bool:
    """True when every facet's BRDF id has analytic partials in the kernels
    (:data:`lightcurve.core.photometry.ANALYTIC_IDS`: Lambert, Cook–Torrance in both diffuse
    forms, Phong)."""
    ids = np.asarray(ids)
    return bool(np.all(np.isin(ids, ANALYTIC_IDS)))


_CHUNK_ELEMENTS = 2_000_000  # epoch-states × facets per block (bounds temporary memory)


def magnitude_partials(shape: Shape, q, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m,
                       sun_mag: float = SUN_MAG_V) -> MagnitudePartials:
    """Magnitude and analytic partials (module docstring); same inputs as
    :func:`~lightcurve.photometry.magnitude.apparent_magnitude` (q (N,4) or (N,S,4)).

    Lambert, Cook–Torrance and Phong facets: analytic partials in one pass over the facets
    (:func:`lightcurve.core.photometry.flux_partials_nb`). Other BRDFs: their products from
    :func:`facet_products`, ∂m/∂ξ, ∂m/∂a, ∂m/∂m NaN, and their contribution to ∂m/∂δθ by a
    central finite difference (step 1e-6 rad).

    Large requests are processed in blocks of epochs so that temporaries stay below about
    a few hundred MB (epochs·states·facets ≤ 2e6 per block); results are concatenated.
    """
    qa = np.asarray(q, float)
    if qa.ndim == 1:
        qa = qa[None, :]
    N = qa.shape[0]
    per_epoch = (qa.shape[1] if qa.ndim == 3 else 1) * shape.n_facets
    step = max(1, _CHUNK_ELEMENTS // max(per_epoch, 1))
    if N <= step:
        return _partials_block(shape, qa, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m,
                               sun_mag)
    s = np.broadcast_to(np.asarray(sun_dir_eci, float).reshape(-1, 3), (N, 3))
    o = np.broadcast_to(np.asarray(obs_dir_eci, float).reshape(-1, 3), (N, 3))
    ro = np.broadcast_to(np.asarray(range_obs_m, float), (N,))
    rs = np.broadcast_to(np.asarray(range_sun_m, float), (N,))
    parts = [_partials_block(shape, qa[i:i + step], s[i:i + step], o[i:i + step],
                             ro[i:i + step], rs[i:i + step], sun_mag) for i in range(0, N, step)]
    return MagnitudePartials(*(np.concatenate([getattr(p, f) for p in parts])
                               for f in MagnitudePartials.__dataclass_fields__))


def _partials_block(shape, qa, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m, sun_mag):
    """One block of :func:`magnitude_partials`."""
    sb3, ob3 = body_directions(qa, sun_dir_eci, obs_dir_eci)          # (N,S,3)
    N, S = sb3.shape[:2]
    sb = np.ascontiguousarray(sb3.reshape(-1, 3))
    ob = np.ascontiguousarray(ob3.reshape(-1, 3))
    M = sb.shape[0]
    F = shape.n_facets
    n, A, ids, p = shape.kernel_arrays()
    ana = np.isin(ids, ANALYTIC_IDS)
    P = np.zeros((M, F))
    dxi = np.full((M, F), np.nan)
    da = np.full((M, F), np.nan)
    dmm = np.full((M, F), np.nan)
    flux = np.zeros(M)
    dth = np.zeros((M, 3))
    if np.any(ana):
        fa, Pa, dxa, daa, dma, dth = partials_many_nb(
            sb, ob, np.ascontiguousarray(n[ana], dtype=float),
            np.ascontiguousarray(A[ana], dtype=float), np.ascontiguousarray(ids[ana], dtype=np.int64),
            np.ascontiguousarray(p[ana], dtype=float))
        flux = fa
        P[:, ana], dxi[:, ana], da[:, ana], dmm[:, ana] = Pa, dxa, daa, dma
    if not np.all(ana):
        idx = np.flatnonzero(~ana)
        sub = _subshape(shape, idx)
        Ao = A[idx]
        Po = facet_products(sub, sb, ob)
        P[:, idx] = Po
        flux = flux + Po @ Ao
        hstep = 1e-6   # finite differences for the BRDFs without analytic partials
        for k in range(3):
            e = np.zeros(3)
            e[k] = hstep
            dqp = rotvec_to_quat(e)
            dqm = rotvec_to_quat(-e)
            fp = facet_products(sub, quat_rotate(dqp, sb), quat_rotate(dqp, ob)) @ Ao
            fm = facet_products(sub, quat_rotate(dqm, sb), quat_rotate(dqm, ob)) @ Ao
            dth[:, k] = dth[:, k] + (fp - fm) / (2.0 * hstep)
    with np.errstate(divide="ignore", invalid="ignore"):
        K = np.where(flux > 0, -2.5 / _LN10 / flux, np.nan)[:, None]
    mag = magnitude_from_flux(flux.reshape(N, S), range_obs_m, range_sun_m, sun_mag)
    lead = (N,) if qa.ndim <= 2 else (N, S)
    return MagnitudePartials(
        m=mag.reshape(lead), flux=flux.reshape(lead), dm_dA=(K * P).reshape(lead + (F,)),
        dm_dxi=(K * A * dxi).reshape(lead + (F,)), dm_da=(K * A * da).reshape(lead + (F,)),
        dm_dm=(K * A * dmm).reshape(lead + (F,)), dm_dtheta=(K * dth).reshape(lead + (3,)))


def _subshape(shape: Shape, idx) -> Shape:
    return Shape(shape.name, shape.areas_m2[idx], shape.normals_body[idx], shape.centers_body_m[idx],
                 [shape.materials[i] for i in idx], shape.mass_kg, shape.inertia_kg_m2,
                 convex=shape.convex, tangents_body=shape.tangents_body[idx])

