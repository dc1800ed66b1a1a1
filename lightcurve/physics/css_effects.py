"""Coarse-sun-sensor effects on CSS voltages (O'Keefe 2015, eq. 2.19–2.21).

The baseline CSS model (:class:`~.context.CSSContext`) is the sensors' cosine response to the
direct Sun, ``y_κ = C C_κ ν f_κ(ŝ)``, with the model's normals and gains. Effects:

* ``css_albedo``: Earth-albedo irradiance ``Σ_j a_j f_κ(ĉ_j)`` (eq. 2.15, 2.21) from an
  albedo map (``albedo = "builtin"`` or a CERES CSV path), times ``albedo_scale``;
* ``css_misalignment``: the true normals are the nominal ones with azimuth and elevation
  offset by δα_κ, δε_κ (eq. 2.19), per sensor, in degrees;
* ``css_scale_factor``: a common scale C and per-sensor scales C_κ multiply the outputs;
* ``css_fault``: sensor κ's output is multiplied by ``gain`` (0: dead) from ``t_start_s`` on.
"""

from __future__ import annotations

import numpy as np

from .registry import Effect, ParamSpec, Prior, register_effect

__all__ = ["CSSAlbedo", "CSSMisalignment", "CSSScaleFactor", "CSSFault"]


@register_effect
class CSSAlbedo(Effect):
    """Earth albedo on the sun sensors: sunlight reflected by the Earth reaches sensors facing the
    Earth and adds a bias that depends on the orbit position and attitude, pulling the sensed
    Sun direction towards the Earth."""

    name = "css_albedo"
    kind = "css"
    group = "reflection"
    params = (ParamSpec("albedo_scale", "1", 1.0, Prior("uniform", 0.7, 1.3), min=0.0, max=5.0, null=0.0,
                        description="multiplier of the albedo map"),)
    options = {"albedo": "builtin", "resolution_deg": 10.0}
    file_options = ("albedo",)  # a CERES/TOMS map path

    def parse_options(self, sec):
        from .earthshine import Earthshine

        return Earthshine.parse_options(self, sec)

    def transform(self, ctx, params):
        from .earthshine import load_grid

        grid = load_grid(self.opts["albedo"], self.opts["resolution_deg"])
        return ctx.with_state(albedo_grid=grid, albedo_scale=float(params["albedo_scale"]))


@register_effect
class CSSMisalignment(Effect):
    """Sun-sensor misalignment: a sensor is mounted slightly tilted from its nominal direction, so
    its output is too high on one side and too low on the other as the Sun moves across it."""

    name = "css_misalignment"
    kind = "css"
    group = "sensor"
    params = (ParamSpec("d_az_deg", "deg", 0.0, Prior("normal", 0.0, 2.0), min=-30.0, max=30.0,
                        per="sensor", null=0.0, description="azimuth offset of each normal (eq. 2.19)"),
              ParamSpec("d_el_deg", "deg", 0.0, Prior("normal", 0.0, 2.0), min=-30.0, max=30.0,
                        per="sensor", null=0.0, description="elevation offset of each normal (eq. 2.19)"))

    def transform(self, ctx, params):
        arr = ctx.array
        mis = arr.misalignment_rad + np.radians(np.stack([params["d_az_deg"], params["d_el_deg"]], axis=1))
        return ctx.with_state(array=arr.with_errors(misalignment_rad=mis))


@register_effect
class CSSScaleFactor(Effect):
    """Sun-sensor scale factors: degraded or mis-calibrated photodiodes report the Sun too weakly
    or too strongly, scaling each sensor's output."""

    name = "css_scale_factor"
    kind = "css"
    group = "illumination"
    # the outputs depend on C·C_k only: the diagnosis fits these products as the individual
    # factors (common held at 1)
    diagnosis_hold = {"common": "only the products C·C_k are identifiable; fitted as the "
                                "individual factors with C = 1"}
    params = (ParamSpec("common", "1", 1.0, Prior("uniform", 0.85, 1.05), min=0.01, max=10.0, null=1.0,
                        description="common scale factor C"),
              ParamSpec("individual", "1", 1.0, Prior("normal", 1.0, 0.05), min=0.01, max=10.0,
                        per="sensor", null=1.0, description="individual scale factors C_k"))

    def transform(self, ctx, params):
        arr = ctx.array
        return ctx.with_state(array=arr.with_errors(
            scale_common=arr.scale_common * float(params["common"]),
            scale_individual=arr.scale_individual * np.asarray(params["individual"], float)))


@register_effect
class CSSFault(Effect):
    """Sun-sensor fault: one sensor fails (stops responding or loses sensitivity) at some time, so
    its output drops while the others stay consistent."""

    name = "css_fault"
    kind = "css"
    group = "sensor"
    params = (ParamSpec("sensor", "index", 0.0, Prior("int_uniform", 0.0, -1.0), min=0.0,
                        max=1e6, integer=True, description="index of the failed sensor"),
              ParamSpec("gain", "1", 0.0, Prior("uniform", 0.0, 0.5), min=0.0, max=10.0, null=1.0,
                        description="output multiplier after the fault (0: dead)"),
              ParamSpec("t_start_s", "s", 0.0, Prior("uniform", 0.0, 1.0), min=0.0, max=1e9,
                        description="time of the fault, s since the epoch"))

    def sample_params(self, rng, ctx=None):
        p = super().sample_params(rng, ctx)
        if ctx is not None and len(ctx):
            p["t_start_s"] = float(np.quantile(ctx.t, p["t_start_s"] * 0.8))  # within the data
        return p

    def transform(self, ctx, params):
        k = int(params["sensor"])
        if k >= ctx.n_sensors:
            raise ValueError(f"css_fault.sensor = {k} but there are {ctx.n_sensors} sensors")
        return ctx.with_state(fault=(k, float(params["gain"]), float(params["t_start_s"])))
