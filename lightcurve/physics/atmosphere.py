"""Atmospheric extinction: the atmosphere dims the object by k magnitudes per air mass.

    Δm = k_site · X(h)

with ``X`` the relative optical air mass of Kasten & Young (1989, Applied Optics 28, 4735,
eq. 3), ``X = 1/(sin h + 0.50572 (h° + 6.07995)^−1.6364)``, valid down to the horizon
(X(0°) ≈ 38; plane-parallel 1/sin h diverges there), and ``k_site`` the extinction
coefficient of each site in the band (V at a good site: 0.12–0.25 mag/air mass; hazy or low
sites up to 0.5). Rows below the horizon (X = NaN) get NaN.
"""

from __future__ import annotations

from .registry import Effect, ParamSpec, Prior, register_effect

__all__ = ["Extinction"]


@register_effect
class Extinction(Effect):
    """Atmospheric extinction: the air between the object and the telescope absorbs and scatters
    light, so the object looks fainter by k magnitudes per air mass, most strongly near the
    horizon."""

    name = "extinction"
    params = (ParamSpec("k_mag_per_airmass", "mag/airmass", 0.2, Prior("uniform", 0.1, 0.4),
                        min=0.0, max=3.0, per="site", null=0.0,
                        description="extinction coefficient of each site in the band"),)
    group = "atmosphere"

    def offset(self, ctx, params):
        """Δm = k_site X (N,), mag."""
        return ctx.site_values(params["k_mag_per_airmass"]) * ctx.airmass

    def signature(self, ctx):
        """The air mass X (N,)."""
        return ctx.airmass
