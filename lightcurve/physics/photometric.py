"""Photometric zero point: a constant magnitude offset per camera (calibration error).

    Δm = δ_camera

e.g. a wrong catalogue zero point, a filter/band mismatch or an uncorrected colour term of
one camera. A recording without a camera column has one camera per site (named after the
site), so the offset is then per site. The signature is the camera indicator (one column
per camera).
"""

from __future__ import annotations

import numpy as np

from .registry import Effect, ParamSpec, Prior, register_effect

__all__ = ["ZeroPoint"]


@register_effect
class ZeroPoint(Effect):
    """Photometric zero-point offset: a calibration error of one camera (or site) makes every
    magnitude it reports brighter or fainter by the same constant amount."""

    name = "zero_point"
    params = (ParamSpec("offset_mag", "mag", 0.0, Prior("signed_uniform", 0.1, 0.4),
                        min=-5.0, max=5.0, per="camera", null=0.0,
                        description="magnitude added to every measurement of the camera"),)
    group = "instrument"

    def offset(self, ctx, params):
        return ctx.camera_values(params["offset_mag"])

    def signature(self, ctx):
        """Ones (N,): a constant offset (split per camera by :meth:`signature_columns`)."""
        return np.ones(len(ctx))
