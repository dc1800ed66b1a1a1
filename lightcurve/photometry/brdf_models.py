"""Built-in analytic BRDFs (registered on import): Lambert, Cook–Torrance, Phong, Ashikhmin–Shirley.

Each class's :meth:`evaluate` calls the numba kernel of :mod:`lightcurve.core.photometry` on flattened arrays,
so the object layer and the hot loop share a single implementation. Frames: ``n``, ``s``,
``o`` are unit vectors in one frame (body axes); ``s`` points object→Sun, ``o``
object→observer. Values in sr⁻¹.
"""

from __future__ import annotations

import numpy as np

from ..core import photometry as K
from .brdf import BRDF, PARAM_COLUMNS, register_brdf

__all__ = ["Lambert", "CookTorrance", "CookTorranceBernard", "Phong", "AshikhminShirley",
           "kernel_brdf_values"]


def kernel_brdf_values(model_id: int, n, s, o, params_rows) -> np.ndarray:
    """f_r (sr⁻¹) of a kernel model for broadcast arrays n, s, o (...,3).

    ``params_rows`` is a packed row (PARAM_COLUMNS,) or rows broadcastable to (..., P).
    Returns 0 where n·s ≤ 0 or n·o ≤ 0.
    """
    n, s, o = np.broadcast_arrays(np.asarray(n, float), np.asarray(s, float), np.asarray(o, float))
    lead = n.shape[:-1]
    p = np.broadcast_to(np.asarray(params_rows, float), lead + (PARAM_COLUMNS,))
    M = int(np.prod(lead)) if lead else 1
    ids = np.full(M, model_id, dtype=np.int64)
    out = K.brdf_value_kernel(ids, np.ascontiguousarray(p.reshape(M, PARAM_COLUMNS)),
                              np.ascontiguousarray(n.reshape(M, 3)),
                              np.ascontiguousarray(s.reshape(M, 3)),
                              np.ascontiguousarray(o.reshape(M, 3)))
    return out.reshape(lead)


class _KernelBRDF(BRDF):
    """A BRDF evaluated by the numba kernel with id ``kernel_id``."""

    def pack_arrays(self, params: dict, lead_shape) -> np.ndarray:
        cols = [np.broadcast_to(np.asarray(params[p], float), lead_shape) for p in self.param_names]
        out = np.zeros(tuple(lead_shape) + (PARAM_COLUMNS,))
        for i, c in enumerate(cols):
            out[..., i] = c
        return out

    def evaluate(self, n, s, o, params: dict):
        n, s, o = np.broadcast_arrays(np.asarray(n, float), np.asarray(s, float),
                                      np.asarray(o, float))
        rows = self.pack_arrays(params, n.shape[:-1])
        return kernel_brdf_values(self.kernel_id, n, s, o, rows)


@register_brdf("lambert")
class Lambert(_KernelBRDF):
    """Lambertian diffuse reflector: f_r = albedo/π [sr⁻¹], albedo ∈ [0, 1]."""

    param_bounds = {"albedo": (0.0, 1.0, False, False)}
    kernel_id = K.LAMBERT


@register_brdf("cook_torrance")
class CookTorrance(_KernelBRDF):
    """Cook–Torrance in the physically consistent form of DESIGN.md (Bernard ch. 5).

    f_r = ξ a/π + (1−ξ) F D G / (4 (n̂·ŝ)(n̂·ô))  [sr⁻¹]

    Parameters: ``xi`` ∈ [0,1] diffuse fraction ξ; ``a`` ∈ (0,1) — both the diffuse albedo
    and the normal-incidence Fresnel reflectance F0 (a = F0, as in the thesis);
    ``m`` ∈ (0,1] Beckmann rms facet slope. D normalised Beckmann, G geometric attenuation
    with min(1, …), F the standard Cook–Torrance Fresnel with c = ô·ĥ,
    g² = n² + c² − 1, n = (1+√F0)/(1−√F0). Departures from thesis slips (eq. 5.8's extra
    (n̂·ŝ) in the diffuse term, eq. 5.10's second denominator) are documented in
    :mod:`lightcurve.core.photometry`.
    """

    param_bounds = {"xi": (0.0, 1.0, False, False), "a": (0.0, 1.0, True, True),
                    "m": (0.0, 1.0, True, False)}
    kernel_id = K.COOK_TORRANCE


@register_brdf("cook_torrance_bernard")
class CookTorranceBernard(CookTorrance):
    """Cook–Torrance with the diffuse term as printed in Bernard (2021) eq. 5.8.

    f_r = ξ a (n̂·ŝ)/π + (1−ξ) F D G / (4 (n̂·ŝ)(n̂·ô))  [sr⁻¹]

    The extra (n̂·ŝ) of eq. 5.8 counts the illumination cosine twice (eq. 5.5 already carries
    it), so :class:`CookTorrance` is the physical default; this form reproduces the thesis's
    own numbers (``variant = "thesis"``). Same parameters, bounds and specular term as
    :class:`CookTorrance` (standard Fresnel, not eq. 5.10's second denominator).
    """

    kernel_id = K.COOK_TORRANCE_THESIS


@register_brdf("phong")
class Phong(_KernelBRDF):
    """Phong in the normalised form f_r = Kd/π + Ks (n+2)/(2π) (r̂·ô)^n  [sr⁻¹].

    r̂ = 2(n̂·ŝ)n̂ − ŝ is the mirror direction; the lobe is zero when r̂·ô < 0.
    Parameters ``Kd``, ``Ks`` ∈ [0, 1], exponent ``n`` ∈ [0, 1e5]. This is the form used by
    Fankhauser et al. (2023) for Starlink (chassis Kd 0.34, Ks 0.40, n 8.9; array Kd 0.15,
    Ks 0.25, n 0.26).
    """

    param_bounds = {"Kd": (0.0, 1.0, False, False), "Ks": (0.0, 1.0, False, False),
                    "n": (0.0, 1e5, False, False)}
    kernel_id = K.PHONG


@register_brdf("ashikhmin_shirley")
class AshikhminShirley(_KernelBRDF):
    """Ashikhmin & Shirley (2000) anisotropic Phong BRDF with its published normalisation.

    ρ = ρ_s + ρ_d with
    ρ_s = √((nu+1)(nv+1))/(8π) · (n̂·ĥ)^[(nu (ĥ·û)² + nv (ĥ·v̂)²)/(1−(n̂·ĥ)²)]
          / ((ĥ·ô) max(n̂·ŝ, n̂·ô)) · [Rs + (1−Rs)(1−ĥ·ô)⁵],
    ρ_d = 28 Rd/(23π) (1−Rs) (1−(1−n̂·ŝ/2)⁵)(1−(1−n̂·ô/2)⁵).

    Parameters ``Rd``, ``Rs`` ∈ [0, 1], ``nu``, ``nv`` ∈ (0, 1e5]. û is the facet's unit
    tangent (body frame; :attr:`Shape.tangents_body`), v̂ = n̂ × û. For :meth:`evaluate`
    pass the tangent as params ``tx, ty, tz`` (default: an arbitrary perpendicular, which is
    irrelevant when nu = nv).
    """

    param_bounds = {"Rd": (0.0, 1.0, False, False), "Rs": (0.0, 1.0, False, False),
                    "nu": (0.0, 1e5, True, False), "nv": (0.0, 1e5, True, False)}
    kernel_id = K.ASHIKHMIN_SHIRLEY

    def evaluate(self, n, s, o, params: dict):
        params = dict(params)
        n, s, o = np.broadcast_arrays(np.asarray(n, float), np.asarray(s, float),
                                      np.asarray(o, float))
        tang = params.pop("tangent", None)
        if tang is None:
            tang = perpendicular_unit(n)
        rows = self.pack_arrays(params, n.shape[:-1])
        rows[..., 4:7] = np.broadcast_to(tang, n.shape)
        return kernel_brdf_values(self.kernel_id, n, s, o, rows)


def perpendicular_unit(n) -> np.ndarray:
    """A deterministic unit vector perpendicular to each unit ``n`` (...,3)."""
    n = np.asarray(n, float)
    # cross with the coordinate axis least aligned with n
    ax = np.zeros_like(n)
    idx = np.argmin(np.abs(n), axis=-1)
    np.put_along_axis(ax, idx[..., None], 1.0, axis=-1)
    t = np.cross(n, ax)
    return t / np.linalg.norm(t, axis=-1, keepdims=True)
