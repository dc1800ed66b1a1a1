"""Unmodelled reflectors: a specular glint facet or an extra diffuse facet.

Both add one flat facet of normal n̂ (body axes, azimuth ``az_deg`` from +x towards +y,
elevation ``el_deg`` from the x–y plane towards +z) to the facet sum:

* ``specular_glint``: a normalised Phong specular lobe,
  ``F = A (n̂·ŝ)(n̂·ô) (k+2)/(2π) max(r̂·ô, 0)^k`` with r̂ = 2(n̂·ŝ)n̂ − ŝ the mirror
  direction (``area_m2`` is the facet area times its specular reflectance, ``exponent`` k
  sets the lobe width ≈ 1/√k rad): short bright flashes when the mirror direction sweeps
  over the observer (solar-array or antenna glints);
* ``unmodelled_facet``: a Lambertian facet, ``F = A ρ/π (n̂·ŝ)(n̂·ô)`` (``area_m2`` = area
  times albedo ρ): a smooth extra brightening (a boom, an antenna, a missing panel).

Both are multiplied by the illumination factor ν like the rest of the sunlight.
"""

from __future__ import annotations

import numpy as np

from .registry import Effect, ParamSpec, Prior, register_effect

__all__ = ["SpecularGlint", "UnmodelledFacet", "facet_normal"]


def facet_normal(az_deg: float, el_deg: float) -> np.ndarray:
    """Unit normal (3,) in body axes from azimuth/elevation in degrees."""
    a, e = np.radians(az_deg), np.radians(el_deg)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


_AZ = ParamSpec("az_deg", "deg", 0.0, Prior("uniform", -180.0, 180.0), min=-360.0, max=360.0,
                description="azimuth of the facet normal in body axes (from +x towards +y)")
_EL = ParamSpec("el_deg", "deg", 0.0, Prior("uniform", -90.0, 90.0), min=-90.0, max=90.0,
                description="elevation of the facet normal in body axes (towards +z)")


class _ExtraFacet(Effect):
    group = "reflection"

    def facet_flux(self, ctx, st, params):
        raise NotImplementedError

    def transform(self, ctx, params):
        p = dict(params)

        def fn(c, st):
            return c.illumination(st) * self.facet_flux(c, st, p)

        return ctx.with_state(extra_flux=ctx.extra_flux + (fn,))

    @staticmethod
    def _dirs(st, params):
        n = facet_normal(params["az_deg"], params["el_deg"])
        sb, ob = st.body_directions()
        sb, ob = sb[:, 0], ob[:, 0]
        return n, sb, ob, sb @ n, ob @ n


@register_effect
class SpecularGlint(_ExtraFacet):
    """Specular glint: a mirror-like surface the model does not have (a solar panel or antenna)
    flashes brightly whenever it reflects the Sun towards the observer."""

    name = "specular_glint"
    params = (ParamSpec("area_m2", "m^2", 0.2, Prior("log_uniform", 0.05, 2.0), min=0.0, max=1e3, null=0.0,
                        description="facet area times specular reflectance"),
              _AZ, _EL,
              ParamSpec("exponent", "1", 100.0, Prior("log_uniform", 20.0, 500.0), min=1.0,
                        max=1e5, description="Phong exponent (lobe width ~ 1/sqrt(k) rad)"))

    def facet_flux(self, ctx, st, params):
        n, sb, ob, ns, no = self._dirs(st, params)
        k = float(params["exponent"])
        ro = 2.0 * ns * no - np.sum(sb * ob, axis=1)
        lobe = (k + 2.0) / (2.0 * np.pi) * np.maximum(ro, 0.0) ** k
        return np.where((ns > 0) & (no > 0), params["area_m2"] * ns * no * lobe, 0.0)


@register_effect
class UnmodelledFacet(_ExtraFacet):
    """Unmodelled surface: a flat diffuse surface missing from the shape model adds light whenever
    it faces both the Sun and the observer."""

    name = "unmodelled_facet"
    params = (ParamSpec("area_m2", "m^2", 0.5, Prior("log_uniform", 0.1, 3.0), min=0.0, max=1e4, null=0.0,
                        description="facet area times Lambert albedo"),
              _AZ, _EL)

    def facet_flux(self, ctx, st, params):
        n, sb, ob, ns, no = self._dirs(st, params)
        return np.where((ns > 0) & (no > 0), params["area_m2"] / np.pi * ns * no, 0.0)
