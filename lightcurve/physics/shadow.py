"""Penumbra: the partial solar disc seen from an object entering or leaving the Earth's shadow.

The baseline model treats the Sun as lit-or-dark (ν = 1 when any of the solar disc is
visible, 0 in the umbra). With this effect the illumination factor is the visible fraction
of the solar disc from the conical shadow model of
:func:`lightcurve.geometry.eclipse.lit_fraction` (Montenbruck & Gill 2000, §3.4.2), with the
shadowing Earth radius enlarged by ``shadow_height_m`` (a crude model of the atmosphere's
opaque lower layers: refraction and absorption near the terminator make the real shadow
≈ 1–2 % larger than the geometric one). The object fades over the ~10 s (LEO) of penumbra
transit: Δm = −2.5 log10 ν.
"""

from __future__ import annotations

import numpy as np

from .registry import Effect, ParamSpec, Prior, register_effect

__all__ = ["Penumbra"]


@register_effect
class Penumbra(Effect):
    """Penumbra: near the edge of the Earth's shadow only part of the Sun's disc is visible from
    the object, so it fades gradually instead of switching off at once."""

    name = "penumbra"
    params = (ParamSpec("shadow_height_m", "m", 0.0, Prior("uniform", 0.0, 50e3),
                        min=0.0, max=200e3, fixable=True,
                        description="height added to the Earth's radius for the shadow (atmosphere)"),)
    group = "illumination"

    def transform(self, ctx, params):
        return ctx.with_state(penumbra=True, shadow_height_m=float(params["shadow_height_m"]))

    def signature(self, ctx):
        """1 − ν (N,): the missing fraction of the solar disc (0 outside the penumbra)."""
        from ..geometry.eclipse import lit_fraction

        lit = lit_fraction(ctx.r_obj_eci_m, ctx.r_sun_eci_m, "conical")
        return np.where(lit > 0, 1.0 - lit, 0.0)
