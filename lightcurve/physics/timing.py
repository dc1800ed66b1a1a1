"""Timing effects: light time, clock offsets and exposure smearing.

* ``light_time``: the light reaching the telescope at ``t`` left the object at
  ``t − τ``, ``τ = |r_site(t) − r_obj(t − τ)|/c`` (solved by two fixed-point iterations;
  LEO: τ ≈ 2–10 ms, the object moves ≈ 15–70 m and turns ω τ). The object's position and
  attitude are evaluated at the emission time.
* ``clock_offset``: the time stamps of a site are late by δ: the measurement labelled ``t``
  was really taken at ``t + δ``, so the whole model (attitude, object, site) is evaluated at
  ``t + δ``. For a fast rotator the residual follows δ·dm/dt.
* ``exposure_smearing``: the telescope integrates the flux over an exposure of ``T`` s
  centred on the time stamp; a rotator's brightness changes during it, so the measured
  magnitude is −2.5 log10 of the *mean flux* (not the mean magnitude). The mean is an
  n-point Gauss–Legendre quadrature (exact for fluxes polynomial in time up to degree
  2n − 1). For small T the change is ≈ −1.086 F''T²/(24 F) mag.
"""

from __future__ import annotations

import numpy as np

from .registry import Effect, ParamSpec, Prior, register_effect

__all__ = ["LightTime", "ClockOffset", "ExposureSmearing"]


@register_effect
class LightTime(Effect):
    """Light travel time: we see the object as it was a few milliseconds earlier, when it was
    elsewhere on its orbit and turned to a slightly different attitude, which shifts fast
    brightness changes in time."""

    name = "light_time"
    params = ()
    group = "timing"

    def transform(self, ctx, params):
        return ctx.with_state(light_time=True)

    def signature(self, ctx):
        """−τ dm/dt (N,): the first-order change, τ = range/c (mag)."""
        from .context import C_LIGHT_M_S

        tau = np.linalg.norm(ctx.r_site_eci_m - ctx.r_obj_eci_m, axis=1) / C_LIGHT_M_S
        return -tau * _dmdt(ctx)


def _dmdt(ctx, h=None):
    """Central difference dm/dt (N,) of the context's model, mag/s (non-finite → 0)."""
    if h is None:
        w = np.linalg.norm(ctx.omega, axis=1) if ctx.omega is not None else np.zeros(len(ctx))
        # a step that turns the body by ≲ 0.5° and is never longer than 0.5 s
        h = np.minimum(0.5, np.radians(0.5) / np.maximum(w, 1e-6))
    mp = ctx.magnitude(t_shift=h)
    mm = ctx.magnitude(t_shift=-h)
    d = (mp - mm) / (2 * h)
    return np.where(np.isfinite(d), d, 0.0)


@register_effect
class ClockOffset(Effect):
    """Clock offset: the time stamps of a site are wrong by a constant amount, so the recorded
    brightness changes appear early or late relative to the model."""

    name = "clock_offset"
    params = (ParamSpec("dt_s", "s", 0.0, Prior("signed_uniform", 0.2, 2.0), min=-120.0,
                        max=120.0, per="site", null=0.0,
                        description="true time minus recorded time (positive: stamps are late)"),)
    group = "timing"

    def transform(self, ctx, params):
        off = ctx.site_values(params["dt_s"])
        if ctx.time_offset_s is not None:
            off = off + ctx.time_offset_s
        return ctx.with_state(time_offset_s=off)

    def signature(self, ctx):
        """dm/dt (N,), mag/s: the residual is ≈ δ · dm/dt."""
        return _dmdt(ctx)


@register_effect
class ExposureSmearing(Effect):
    """Exposure smearing: the camera averages the light over the exposure, so the fast flashes and
    dips of a rotating object are smoothed out and peaks look fainter."""

    name = "exposure_smearing"
    params = (ParamSpec("exposure_s", "s", 1.0, Prior("uniform", 1.0, 10.0), min=0.0, max=600.0,
                        per="site", null=0.0, description="exposure time centred on the time stamp"),)
    options = {"n_nodes": 12}
    group = "timing"

    def parse_options(self, sec):
        return {"n_nodes": sec.int("n_nodes", 12, min=1, max=200)}

    def transform(self, ctx, params):
        return ctx.with_state(exposure_s=ctx.site_values(params["exposure_s"]),
                              exposure_nodes=int(self.opts["n_nodes"]))

    def signature(self, ctx):
        """Second-order small-exposure change per s² of exposure (N,), mag/s².

        ⟨F⟩ ≈ F + F''T²/24, and with F ∝ 10^(−0.4 m): F''/F = (0.4 ln10 ṁ)² − 0.4 ln10 m̈, so
        Δm ≈ −(2.5/ln10) (T²/24) F''/F. Returned for T = 1 s (scale by T²). It grows with
        the rotation rate squared (the |ω|·T of a flash crossing the exposure).
        """
        w = np.linalg.norm(ctx.omega, axis=1) if ctx.omega is not None else np.zeros(len(ctx))
        h = np.minimum(0.5, np.radians(0.5) / np.maximum(w, 1e-6))
        m0 = ctx.magnitude()
        mp = ctx.magnitude(t_shift=h)
        mm = ctx.magnitude(t_shift=-h)
        d1 = (mp - mm) / (2 * h)
        d2 = (mp - 2 * m0 + mm) / h**2
        c = 0.4 * np.log(10.0)
        f2 = (c * d1) ** 2 - c * d2
        s = -(2.5 / np.log(10.0)) / 24.0 * f2
        return np.where(np.isfinite(s), s, 0.0)
