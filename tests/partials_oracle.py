"""NumPy oracle of the magnitude partials (a test reference, not production code).

The vectorised NumPy algebra of ∂m/∂(A, ξ, a, m, δθ) for Lambert, Cook–Torrance and Phong
facets (Bernard 2021 eq. 8.19–8.33 in the consistent form of DESIGN.md; module docstring of
:mod:`lightcurve.photometry.partials`), written independently of the numba kernels of
:mod:`lightcurve.core.photometry` — Cook–Torrance gradients by the explicit branch formulas of G
rather than the kernel's chain rule. Other BRDFs get a central finite difference (1e-6 rad) for
the attitude partial, as in the production code.
"""

from __future__ import annotations

import numpy as np

from lightcurve.core.photometry import COOK_TORRANCE, LAMBERT, PHONG, fresnel_xyz
from lightcurve.photometry.facets import Shape
from lightcurve.photometry.magnitude import SUN_MAG_V, body_directions, magnitude_from_flux
from lightcurve.photometry.partials import MagnitudePartials, facet_products
from lightcurve.rotations import quat_rotate, rotvec_to_quat

_LN10 = np.log(10.0)


def _fresnel_and_derivs(c, f0):
    """F(c; F0), ∂F/∂c and ∂F/∂F0 elementwise (the core's scalar Fresnel on each element)."""
    c, f0 = np.broadcast_arrays(np.asarray(c, dtype=float), np.asarray(f0, dtype=float))
    vals = [fresnel_xyz(float(ci), float(fi)) for ci, fi in zip(c.ravel(), f0.ravel())]
    out = np.array(vals, dtype=float).reshape(c.shape + (3,))
    return out[..., 0], out[..., 1], out[..., 2]


def magnitude_partials_numpy(shape, q, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m,
                             sun_mag=SUN_MAG_V):
    """Same inputs and outputs as :func:`lightcurve.photometry.magnitude_partials`."""
    qa = np.asarray(q, float)
    if qa.ndim == 1:
        qa = qa[None, :]
    return _partials_block(shape, qa, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m, sun_mag)


def _partials_block(shape, qa, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m, sun_mag):
    """NumPy algebra (any BRDF; FD attitude partials for BRDFs without analytic ones)."""
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
        # the specular lobe is weighted by (1 − ξ): zero at ξ = 1 but its ξ-derivative is not
        spec = (nhc > 0) & (cc > 0)
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

