"""Switch a scenario's ``[effects]`` on in the simulator (used by :mod:`lightcurve.studies.simulate`).

Order (:data:`lightcurve.physics.registry.ORDER`): illumination (penumbra) → reflection
(Earthshine, glints, unmodelled facets) → occlusion (self-shadowing) → timing (light time,
clock offset, exposure smearing) → atmosphere (extinction) → instrument (zero point). The
effects act on the noise-free magnitudes; the simulator adds the noise afterwards
(σ = m·r/3 of the affected magnitude, Bernard eq. 9.3).
"""

from __future__ import annotations

import numpy as np

from .context import ModelContext
from .registry import apply_effects, effects_to_json, parse_effects

__all__ = ["apply_scenario_effects", "scenario_context"]


def scenario_context(scenario, geo, q, omega) -> ModelContext:
    """The :class:`ModelContext` of simulated rows (truth attitude, constant-rate shifts)."""
    return ModelContext.from_geometry(geo, scenario.shape, q, omega,
                                      sun_mag=scenario.measurement.sun_mag,
                                      ignore_eclipse=scenario.measurement.ignore_eclipse)


def apply_scenario_effects(scenario, geo, q, omega, m_true, rows):
    """Noise-free magnitudes with the scenario's effects on, for the selected rows.

    Parameters: ``geo`` ObservationGeometry of all scheduled rows; ``q`` (N,4), ``omega``
    (N,3) truth attitude and body rate; ``m_true`` (N,) baseline magnitudes; ``rows`` (N,)
    bool — only these rows (the measurable ones) are re-evaluated.

    Returns ``(m_new (N,), effects_json)`` where the JSON records every effect with all its
    parameter values (defaults filled in) and options, in application order.
    """
    site_names = [s.id for s in geo.sites]
    configured = parse_effects(scenario.effects, file=scenario.source, site_names=site_names)
    m_new = np.array(m_true, float, copy=True)
    idx = np.flatnonzero(rows)
    if configured and idx.size:
        ctx = scenario_context(scenario, geo.subset(idx), q[idx], omega[idx])
        for c in configured:
            c.params = c.effect.check_params(c.params, ctx)
        m_new[idx] = apply_effects(ctx, configured)
    else:
        for c in configured:
            c.params = c.effect.check_params(c.params, _Sizes(len(site_names)))
    return m_new, effects_to_json(configured, site_names)


class _Sizes:
    def __init__(self, n_sites):
        self.n_sites = n_sites
        self.n_sensors = None
