"""Apparent magnitude of a faceted object (Bernard eq. 5.2–5.6, physically consistent form).

    m = m_sun − 2.5 log10( Σ_i A_i max(n̂_i·ŝ,0) max(n̂_i·ô,0) f_r,i / |r_obs|² )
          + 5 log10(|r_sun| / 1 au)

ŝ: unit object→Sun, ô: unit object→observer, both rotated into body axes with the attitude
``q`` (scalar first, inertial→body, ``v_b = A(q) v_I``); |r_obs| object–observer distance and
|r_sun| object–Sun distance in metres; f_r in sr⁻¹; m_sun the Sun's apparent magnitude in the
band at 1 au (V: −26.74). Facets are summed independently (convex objects; no
self-shadowing). An object that reflects nothing towards the observer (every facet facing
away from the Sun or the observer) has zero flux and **m = +inf**; callers decide what an
invisible object means (the simulator flags it).
"""

from __future__ import annotations

import numpy as np

from ..core.constants import AU_M, SUN_MAG_V
from ..core.photometry import brightness_kernel
from ..rotations import quat_rotate
from .facets import Shape

__all__ = ["AU_M", "SUN_MAG_V", "apparent_magnitude", "flux_factor", "magnitude_from_flux",
           "body_directions"]



def _unit(v, name):
    v = np.asarray(v, float)
    if v.ndim == 0 or v.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape (..., 3), got {v.shape}")
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if not np.all(np.isfinite(v)) or np.any(n == 0):
        raise ValueError(f"{name}: contains zero, NaN or infinite vectors")
    if not np.allclose(n, 1.0, atol=1e-6):
        raise ValueError(f"{name}: expected unit vectors (to 1e-6)")
    return v


def body_directions(q, sun_dir_eci, obs_dir_eci):
    """Rotate ECI unit directions into body axes for every epoch and state.

    q: (N,4) or (N,S,4) inertial→body scalar-first; directions (N,3) ECI.
    Returns s_body, o_body as (N,S,3) contiguous arrays (S = 1 for (N,4) input).
    """
    q = np.asarray(q, float)
    s = _unit(sun_dir_eci, "sun_dir_eci")
    o = _unit(obs_dir_eci, "obs_dir_eci")
    if q.ndim == 1:
        q = q[None, :]
    if q.ndim == 2:
        q = q[:, None, :]
    if q.ndim != 3 or q.shape[-1] != 4:
        raise ValueError(f"q: expected shape (N,4) or (N,S,4), got {q.shape}")
    N = q.shape[0]
    s = np.broadcast_to(s.reshape(-1, 3), (N, 3))
    o = np.broadcast_to(o.reshape(-1, 3), (N, 3))
    sb = np.ascontiguousarray(quat_rotate(q, s[:, None, :]))
    ob = np.ascontiguousarray(quat_rotate(q, o[:, None, :]))
    return sb, ob


def flux_factor(shape: Shape, s_body, o_body) -> np.ndarray:
    """Σ_i A_i max(n̂_i·ŝ,0) max(n̂_i·ô,0) f_r,i  [m² sr⁻¹] for body-frame directions (N,S,3).

    Kernel BRDFs go through :func:`~.kernels.brightness_kernel`; other BRDFs (tabulated,
    user-registered) are evaluated in numpy and added.
    """
    sb = np.ascontiguousarray(s_body, dtype=float)
    ob = np.ascontiguousarray(o_body, dtype=float)
    if sb.ndim != 3 or sb.shape != ob.shape or sb.shape[-1] != 3:
        raise ValueError(f"s_body and o_body must both be (N,S,3); got {sb.shape}, {ob.shape}")
    n, a, ids, p = shape.kernel_arrays()
    total = brightness_kernel(n, a, ids, p, sb, ob)
    for brdf, idx in shape.numpy_groups:
        nf = shape.normals_body[idx]                       # (G,3)
        ns = np.einsum("nsk,gk->nsg", sb, nf)
        no = np.einsum("nsk,gk->nsg", ob, nf)
        vis = (ns > 0) & (no > 0)
        if not np.any(vis):
            continue
        params = {k: shape.param_table[k][idx] for k in brdf.param_names}
        f = brdf.evaluate(nf[None, None, :, :], sb[:, :, None, :], ob[:, :, None, :], params)
        total += np.where(vis, shape.areas_m2[idx] * ns * no * f, 0.0).sum(-1)
    return total


def magnitude_from_flux(flux, range_obs_m, range_sun_m, sun_mag: float = SUN_MAG_V):
    """m = sun_mag − 2.5 log10(flux/|r_obs|²) + 5 log10(|r_sun|/au); flux ≤ 0 → +inf.

    flux (N,) or (N,S) in m² sr⁻¹; ranges (N,) in metres (broadcast over S).
    """
    flux = np.asarray(flux, float)
    ro = np.asarray(range_obs_m, float)
    rs = np.asarray(range_sun_m, float)
    if np.any(~(ro > 0)) or np.any(~(rs > 0)):
        raise ValueError("ranges must be positive and finite")
    if flux.ndim == 2:
        ro = ro.reshape(-1, 1) if ro.ndim else ro
        rs = rs.reshape(-1, 1) if rs.ndim else rs
    with np.errstate(divide="ignore"):
        m = sun_mag - 2.5 * np.log10(np.where(flux > 0, flux, 0.0) / ro**2) + 5.0 * np.log10(rs / AU_M)
    return np.where(flux > 0, m, np.inf)


def apparent_magnitude(shape: Shape, q, sun_dir_eci, obs_dir_eci, range_obs_m, range_sun_m,
                       sun_mag: float = SUN_MAG_V) -> np.ndarray:
    """Apparent magnitude of ``shape`` (module docstring equation).

    Parameters
    ----------
    shape : Shape
    q : (N,4) or (N,S,4)
        Attitude quaternions, scalar first, inertial(ECI)→body; S states per epoch
        (particles, sigma points).
    sun_dir_eci, obs_dir_eci : (N,3)
        Unit vectors object→Sun and object→observer in ECI (GCRS).
    range_obs_m, range_sun_m : (N,)
        Object–observer and object–Sun distances, m.
    sun_mag : float
        Apparent magnitude of the Sun at 1 au in the band (V: −26.74).

    Returns
    -------
    (N,) for (N,4) input, (N,S) for (N,S,4). +inf where no light is reflected towards the
    observer.
    """
    qa = np.asarray(q, float)
    sb, ob = body_directions(qa, sun_dir_eci, obs_dir_eci)
    flux = flux_factor(shape, sb, ob)
    m = magnitude_from_flux(flux, range_obs_m, range_sun_m, sun_mag)
    return m[:, 0] if qa.ndim <= 2 else m
