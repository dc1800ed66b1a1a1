"""Physics effects: optional physics that changes what is measured (DESIGN.md).

One registry serves simulation (the scenario's ``[effects]`` table switches effects on in
``lightcurve simulate``) and diagnosis (effects are proposed, scored by their signature and
fitted). Public API::

    available_effects(kind=None) -> list[str]      # "magnitude" or "css" effects
    get_effect(name, **options) -> Effect          # .params, .description, .apply(ctx, params),
                                                   # .signature(ctx), .sample_params(rng, ctx)
    register_effect(cls)                           # class decorator for new effects
    ModelContext, CSSContext                       # baseline model + effect state
    apply_effects(ctx, configured) -> measurements # several effects in the documented ORDER
    parse_effects(raw, file, site_names) -> [ConfiguredEffect]
    effects_to_json(configured, site_names) -> str

Magnitude effects: extinction, zero_point, penumbra, earthshine, self_shadowing, light_time,
clock_offset, exposure_smearing, specular_glint, unmodelled_facet. CSS effects: css_albedo,
css_misalignment, css_scale_factor, css_fault.
"""

from .context import CSSContext, GeometryState, ModelContext
from .registry import (ORDER, ConfiguredEffect, Effect, ParamSpec, Prior, apply_effects,
                       available_effects, effect_class, effects_to_json, get_effect,
                       parse_effects, register_effect)

__all__ = ["ModelContext", "CSSContext", "GeometryState", "Effect", "ParamSpec", "Prior",
           "ConfiguredEffect", "ORDER", "apply_effects", "available_effects", "effect_class",
           "effects_to_json", "get_effect", "parse_effects", "register_effect"]
