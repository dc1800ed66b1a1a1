"""Earth's shadow: illuminated fraction of the solar disc seen from an object.

Conical model (Montenbruck & Gill 2000, §3.4.2, geometry of two overlapping discs): seen from
the object at ``r`` (geocentric, m) the Sun (radius R☉, at ``s − r``) and the Earth (radius
R⊕, at ``−r``) subtend angular radii

    a = asin(R☉ / |s − r|),   b = asin(R⊕ / |r|),

with centre separation ``c = ∠(s − r, −r)``. The visible fraction of the solar disc is

* 1                         if c ≥ a + b                (sunlit),
* 0                         if c ≤ b − a               (umbra),
* 1 − (b/a)²                if c ≤ a − b               (antumbra / annular: Earth inside the disc),
* 1 − A_overlap / (π a²)    otherwise                  (penumbra),

with the flat-disc circle-intersection area ``A_overlap`` (exact for two circles in the
small-angle limit; the Sun's angular radius is < 0.27° so the error is negligible). No
limb darkening, no atmosphere (refraction and absorption near the terminator; set
``earth_radius_m`` to R⊕ + ~50 km for a crude atmospheric shadow).

Cylindrical model: the shadow is the cylinder of radius R⊕ behind the Earth along the Sun
line; lit fraction 0 inside, 1 outside (no penumbra).
"""

from __future__ import annotations

import numpy as np

__all__ = ["R_SUN_M", "R_EARTH_SHADOW_M", "lit_fraction", "shadow_region", "LIT", "PENUMBRA",
           "UMBRA", "ANTUMBRA"]

R_SUN_M = 6.957e8
"""Nominal solar radius (IAU 2015 Resolution B3), m."""
R_EARTH_SHADOW_M = 6378137.0
"""Earth radius used for the shadow (WGS84 equatorial), m."""

LIT, PENUMBRA, UMBRA, ANTUMBRA = 0, 1, 2, 3


def _prep(r_obj_m, r_sun_m):
    r = np.atleast_2d(np.asarray(r_obj_m, dtype=float))
    s = np.atleast_2d(np.asarray(r_sun_m, dtype=float))
    if r.shape[-1] != 3 or s.shape[-1] != 3:
        raise ValueError("r_obj_m and r_sun_m must have shape (3,) or (N, 3)")
    r, s = np.broadcast_arrays(r, s)
    return r, s


def _discs(r, s, earth_radius_m, sun_radius_m):
    d_sun = s - r
    ds = np.linalg.norm(d_sun, axis=-1)
    rn = np.linalg.norm(r, axis=-1)
    if np.any(rn <= earth_radius_m):
        raise ValueError("an object position is inside the Earth (|r| <= earth_radius_m)")
    a = np.arcsin(np.clip(sun_radius_m / ds, 0, 1))
    b = np.arcsin(np.clip(earth_radius_m / rn, 0, 1))
    cosc = -np.sum(d_sun * r, -1) / (ds * rn)
    c = np.arccos(np.clip(cosc, -1.0, 1.0))
    return a, b, c


def lit_fraction(r_obj_m, r_sun_m, model: str = "conical", *,
                 earth_radius_m: float = R_EARTH_SHADOW_M,
                 sun_radius_m: float = R_SUN_M) -> np.ndarray:
    """Fraction (0…1) of the solar disc visible from the object, ``(N,)``.

    Parameters
    ----------
    r_obj_m : array (N, 3) or (3,)
        Geocentric object position (GCRS, m).
    r_sun_m : array (N, 3) or (3,)
        Geocentric Sun position (GCRS, m), same epochs.
    model : {"conical", "cylindrical"}
        Shadow model (module docstring).

    Notes
    -----
    The fraction of the solar *disc* (uniform disc, no limb darkening) is what scales the
    irradiance reaching the object.
    """
    r, s = _prep(r_obj_m, r_sun_m)
    if model == "cylindrical":
        shat = s / np.linalg.norm(s, axis=-1, keepdims=True)
        along = np.sum(r * shat, -1)
        perp = np.linalg.norm(r - along[:, None] * shat, axis=-1)
        return np.where((along < 0) & (perp < earth_radius_m), 0.0, 1.0)
    if model != "conical":
        raise ValueError(f"unknown shadow model {model!r}; allowed: conical, cylindrical")
    a, b, c = _discs(r, s, earth_radius_m, sun_radius_m)
    frac = np.ones_like(c)
    umbra = c <= b - a
    annular = (c <= a - b) & ~umbra
    partial = (c < a + b) & ~umbra & ~annular
    frac[umbra] = 0.0
    frac[annular] = 1.0 - (b[annular] / a[annular]) ** 2
    if np.any(partial):
        ap, bp, cp = a[partial], b[partial], c[partial]
        # area of intersection of circles radii ap, bp with centre distance cp
        x = (cp * cp + ap * ap - bp * bp) / (2 * cp)
        y = np.sqrt(np.maximum(ap * ap - x * x, 0.0))
        area = (ap * ap * np.arccos(np.clip(x / ap, -1, 1))
                + bp * bp * np.arccos(np.clip((cp - x) / bp, -1, 1)) - cp * y)
        frac[partial] = 1.0 - area / (np.pi * ap * ap)
    return np.clip(frac, 0.0, 1.0)


def shadow_region(r_obj_m, r_sun_m, *, earth_radius_m: float = R_EARTH_SHADOW_M,
                  sun_radius_m: float = R_SUN_M) -> np.ndarray:
    """Conical shadow region per epoch: ``LIT`` 0, ``PENUMBRA`` 1, ``UMBRA`` 2, ``ANTUMBRA`` 3."""
    r, s = _prep(r_obj_m, r_sun_m)
    a, b, c = _discs(r, s, earth_radius_m, sun_radius_m)
    out = np.full(c.shape, LIT, dtype=np.int8)
    out[c < a + b] = PENUMBRA
    out[(c <= a - b)] = ANTUMBRA
    out[c <= b - a] = UMBRA
    return out
