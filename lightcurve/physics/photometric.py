"""Photometric zero point: a constant magnitude offset per site (calibration error).

    Δm = δ_site

e.g. a wrong catalogue zero point, a filter/band mismatch or an uncorrected colour term at
one observatory. The signature is the site indicator (one column per site).
"""

from __future__ import annotations

import numpy as np

from .registry import Effect, ParamSpec, Prior, register_effect

__all__ = ["ZeroPoint"]


@register_effect
class ZeroPoint(Effect):
    name = "zero_point"
    description = ("Photometric zero-point offset: a calibration error at one site makes every "
                   "magnitude it reports brighter or fainter by the same constant amount.")
    params = (ParamSpec("offset_mag", "mag", 0.0, Prior("signed_uniform", 0.1, 0.4),
                        min=-5.0, max=5.0, per="site",
                        description="magnitude added to every measurement of the site"),)
    group = "instrument"

    def offset(self, ctx, params):
        return ctx.site_values(params["offset_mag"])

    def signature(self, ctx):
        """Ones (N,): a constant offset (split per site by :meth:`signature_columns`)."""
        return np.ones(len(ctx))
