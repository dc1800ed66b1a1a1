"""Simulate an apparent-magnitude lightcurve from a scenario.

Pipeline (DESIGN.md data flow): schedule of epochs per site → object orbit → observation
geometry (Sun, sites, eclipse, visibility) → truth attitude → noise-free magnitudes (Bernard
eq. 5.2–5.6 in the consistent form of DESIGN.md, scaled by the lit fraction of the solar disc
unless ``ignore_eclipse``) → noise σ = m·r/3 (eq. 9.3) → :class:`~lightcurve.io.Lightcurve`.

Epochs where the object is below the site's elevation limit, where the site is not dark (when
required) or where the object is in the Earth's shadow (unless ``ignore_eclipse``) are dropped
and counted; a scenario with no usable epoch is an :class:`InputError`. An unlit pass always
produces a loud :class:`EclipseWarning` — with ``ignore_eclipse`` the magnitudes are computed as
if the object were in full sunlight (how Bernard's published cases were generated).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..io.lightcurve_h5 import Lightcurve
from .scenario import Scenario

__all__ = ["simulate", "EclipseWarning", "initial_attitude", "truth_attitude", "SimulationCounts"]


from ..geometry.visibility import UnlitPassWarning as EclipseWarning  # noqa: E402  one warning class


@dataclass
class SimulationCounts:
    """How many scheduled epochs were kept or dropped, and why."""

    scheduled: int
    below_horizon: int
    site_daylight: int
    eclipsed: int
    kept: int
    no_reflection: int = 0   # lit and visible, but no lit facet faces the observer


def _rngs(seed: int):
    ss = np.random.SeedSequence(int(seed))
    att, noise = ss.spawn(2)
    return np.random.default_rng(att), np.random.default_rng(noise)


def initial_attitude(scenario: Scenario):
    """Initial truth quaternion (inertial→body) and body rate (rad/s) at the epoch.

    With ``attitude.frame = "nadir"`` the Euler angles and rates are relative to the nadir
    (LVLH) frame of the orbit at the epoch (:func:`lightcurve.geometry.frames.nadir_dcm`):
    ``A_BI = A_BN A_NI`` and ``ω_B = A_BN ω_NI + ω_rel`` with ``ω_NI = [0, −|r×v|/|r|², 0]`` in
    nadir axes (the frame turns about the orbit normal; its y axis is the negative normal).
    """
    from ..geometry.frames import nadir_dcm
    from ..rotations import dcm_to_quat, euler321_to_quat, quat_mult, quat_rotate

    at = scenario.attitude
    q_rel = euler321_to_quat(np.radians(at.euler321_deg))
    w_rel = np.radians(at.omega_deg_s)
    if at.frame == "inertial":
        return q_rel, w_rel
    r, v = scenario.orbit.positions(scenario.epoch_utc, np.array([0.0]))
    q_ni = dcm_to_quat(nadir_dcm(r[0], v[0]))
    rate = np.linalg.norm(np.cross(r[0], v[0])) / np.dot(r[0], r[0])
    w_ni = np.array([0.0, -rate, 0.0])
    return quat_mult(q_rel, q_ni), quat_rotate(q_rel, w_ni) + w_rel


def truth_attitude(scenario: Scenario, t_s: np.ndarray, rng, r_obj_eci_m=None, v_obj_eci_m=None,
                   r_sun_eci_m=None, lit_fraction=None):
    """Truth quaternions (N,4) and body rates (N,3, rad/s) at sorted unique times ``t_s``.

    ``t_s`` counts seconds from the scenario epoch and must be ≥ 0: the initial attitude
    (:func:`initial_attitude`) holds AT the epoch (``t0_s = 0``) and is propagated to every
    requested time, whatever the first requested time is.
    """
    from ..dynamics import ControlledTruth, UncontrolledTruth
    at = scenario.attitude
    if at.dynamics == "law":  # attitude prescribed by geometry (lightcurve.dynamics.laws)
        from ..dynamics.laws import attitude_law, law_body_rates
        from ..geometry.time import sun_position_gcrs

        r = scenario.orbit.positions(scenario.epoch_utc, t_s)[0] if r_obj_eci_m is None else r_obj_eci_m
        r_sun = sun_position_gcrs(scenario.epoch_utc, t_s) if r_sun_eci_m is None else r_sun_eci_m
        q = attitude_law(at.law, r, r_sun, scenario.epoch_utc, t_s)
        return q, law_body_rates(q, t_s)
    q0, w0 = initial_attitude(scenario)
    if at.dynamics == "controlled":
        model = ControlledTruth(q0, w0, np.radians(at.acs_sigma_deg), rng, t0_s=0.0,
                                mode=at.acs_mode)
        return model.simulate(t_s)
    J = at.inertia_kg_m2 if at.inertia_kg_m2 is not None else scenario.shape.inertia_kg_m2
    model = UncontrolledTruth(q0, w0, J, torques=at.torques, eta_sigma_rad_s2=np.radians(at.eta_sigma_deg_s2),
                              rng=rng, shape=scenario.shape, orbit=scenario.orbit,
                              epoch_utc=scenario.epoch_utc, t0_s=0.0,
                              torque_forms=at.torque_forms)
    return model.simulate(t_s)


def simulate(scenario, seed: int | None = None, return_counts: bool = False):
    """Simulate the scenario's lightcurve (also ``lightcurve.simulate``).

    Parameters
    ----------
    scenario : Scenario, path or bundled name
        A :class:`~lightcurve.studies.scenario.Scenario`, a scenario TOML file or a bundled
        scenario name (``"default"``, ``"thesis"``, ``"thesis/<case>"``;
        :func:`lightcurve.studies.scenario.resolve_scenario`).
    seed : int, optional
        Overrides ``scenario.seed``. The attitude noise and the measurement noise use two
        independent streams spawned from it, so the result is reproducible bit for bit.
    return_counts : bool
        Also return a :class:`SimulationCounts`.

    Returns
    -------
    Lightcurve (and SimulationCounts)
    """
    from ..geometry.observation import compute_geometry
    from ..geometry.schedules import build_schedule
    from ..photometry import apparent_magnitude
    from ..photometry.noise import magnitude_sigma
    from .scenario import load_scenario, resolve_scenario

    if not isinstance(scenario, Scenario):
        scenario = load_scenario(resolve_scenario(scenario))
    if scenario.orbit is None:
        raise InputError("this scenario has no [orbit] (it models a recording); add an [orbit] to "
                         "simulate", file=scenario.source, field="orbit")
    seed = scenario.seed if seed is None else int(seed)
    rng_att, rng_noise = _rngs(seed)
    meas = scenario.measurement
    nominal_shape = scenario.shape  # the file carries the nominal (model) shape
    refl_truth = None
    refl = getattr(scenario, "reflection", None)
    if refl is not None and refl.perturb:
        # [reflection] (Bernard §10.1): the truth shape's parameters are perturbed; own stream,
        # independent of the attitude and noise streams (their draws are unchanged)
        import json

        from ..photometry.perturb import perturb_reflection

        rng_refl = np.random.default_rng(np.random.SeedSequence([int(seed), 0x2EF1EC7]))
        shape_true, vals = perturb_reflection(scenario.shape, rng_refl, frac=refl.sigma_frac,
                                              kinds=refl.params)
        refl_truth = json.dumps({k: [None if np.isnan(x) else float(x) for x in v]
                                 for k, v in vals.items()})
        scenario = replace(scenario, shape=shape_true)

    t, site_idx = build_schedule(scenario.duration_s, scenario.cadence_s,
                                 [s.windows_s for s in scenario.sites])
    if len(t) == 0:
        raise InputError("no epoch falls inside any site's windows_s", file=scenario.source,
                         field="sites.windows_s")
    sites = [s.site for s in scenario.sites]
    tu, inv = np.unique(t, return_inverse=True)
    r_u, v_u = scenario.orbit.positions(scenario.epoch_utc, tu)
    r_obj, v_obj = r_u[inv], v_u[inv]
    geo = compute_geometry(scenario.epoch_utc, t, site_idx, sites, r_obj, v_obj,
                           twilight_deg=meas.twilight_deg)

    above = geo.elevation_rad >= np.radians(meas.min_elevation_deg)
    if any(getattr(s, "horizon_mask", None) is not None for s in sites):
        above &= geo.above_horizon
    dark = geo.sun_elevation_rad <= np.radians(meas.twilight_deg) if meas.require_dark_site \
        else np.ones(len(t), bool)
    lit = geo.lit_fraction > 0.0
    unlit_visible = above & dark & ~lit
    n_sched = len(t)
    if np.any(unlit_visible):
        frac = np.mean(~lit[above & dark]) if np.any(above & dark) else 1.0
        msg = (f"{scenario.name or 'scenario'}: the object is in the Earth's shadow for "
               f"{100 * frac:.0f}% of the visible epochs ({int(np.sum(unlit_visible))} of "
               f"{int(np.sum(above & dark))}). ")
        if meas.ignore_eclipse:
            msg += "measurement.ignore_eclipse = true: magnitudes are computed AS IF SUNLIT."
        else:
            msg += "Those epochs are dropped; set measurement.ignore_eclipse = true to reproduce " \
                   "published cases that ignored the eclipse."
        warnings.warn(msg, EclipseWarning, stacklevel=2)
    keep = above & dark & (lit | meas.ignore_eclipse)
    counts = SimulationCounts(scheduled=n_sched, below_horizon=int(np.sum(~above)),
                              site_daylight=int(np.sum(above & ~dark)),
                              eclipsed=int(np.sum(above & dark & ~lit & ~meas.ignore_eclipse)),
                              kept=int(np.sum(keep)))
    if not np.any(keep):
        raise InputError(
            f"no visible measurement: of {n_sched} scheduled epochs {counts.below_horizon} are below "
            f"the elevation limit, {counts.site_daylight} have the Sun above {meas.twilight_deg}° at "
            f"the site and {counts.eclipsed} are in the Earth's shadow",
            file=scenario.source, field="sites / measurement")

    q_u, w_u = truth_attitude(scenario, tu, rng_att, r_u, v_u)
    q, w = q_u[inv], w_u[inv]

    # baseline illumination is lit-or-dark; the partial solar disc is the penumbra effect
    lit_frac = np.ones(len(t)) if meas.ignore_eclipse else (geo.lit_fraction > 0).astype(float)
    with np.errstate(divide="ignore"):
        m_true = apparent_magnitude(scenario.shape, q, geo.obj_to_sun_unit, geo.obj_to_obs_unit,
                                    geo.range_obs_m, geo.range_sun_m, sun_mag=meas.sun_mag)
        m_true = m_true - 2.5 * np.log10(np.where(lit_frac > 0, lit_frac, np.nan))
    effects_json = None
    if scenario.effects:  # physics effects on the noise-free magnitudes (lightcurve.physics)
        from ..physics.simulation import apply_scenario_effects

        m_true, effects_json = apply_scenario_effects(scenario, geo, q, w, m_true,
                                                      keep & np.isfinite(m_true))
    # no reflected light towards the observer (all lit facets face away): not measurable
    dark_obj = ~np.isfinite(m_true)
    n_no_reflection = int(np.sum(keep & dark_obj))  # only epochs not already dropped above
    keep &= ~dark_obj
    counts = replace(counts, no_reflection=n_no_reflection, kept=int(np.sum(keep)))
    if not np.any(keep):
        raise InputError("no visible measurement: no lit facet faces the observer at any epoch",
                         file=scenario.source, field="attitude")
    sigma = magnitude_sigma(np.where(np.isfinite(m_true), m_true, 0.0), meas.r_percent)
    noise = rng_noise.standard_normal(len(t))  # drawn for all scheduled rows: stable streams
    mag = m_true + sigma * noise

    k = keep
    lla = np.array([[s.lat_deg, s.lon_deg, s.height_m] for s in sites])
    lc = Lightcurve(
        epoch_utc=scenario.epoch_utc, t=t[k], mag=mag[k], mag_sigma=sigma[k], site=site_idx[k],
        site_names=[s.id for s in sites], site_lla_deg_m=lla,
        r_obj_eci_m=geo.r_obj_eci_m[k], r_site_eci_m=geo.r_site_eci_m[k], r_sun_eci_m=geo.r_sun_eci_m[k],
        lit_fraction=geo.lit_fraction[k], elevation_rad=geo.elevation_rad[k],
        truth_q=q[k], truth_omega_rad_s=w[k], truth_mag=m_true[k],
        scenario_toml=scenario.text,
        attrs={"shape": getattr(scenario.shape, "name", ""), "r_percent": meas.r_percent,
               "seed": seed, "ignore_eclipse": int(meas.ignore_eclipse), "sun_mag": meas.sun_mag,
               "dropped_below_horizon": counts.below_horizon, "dropped_site_daylight": counts.site_daylight,
               "dropped_eclipsed": counts.eclipsed, "dropped_no_reflection": n_no_reflection},
        shape=nominal_shape,
    )
    if getattr(meas, "band", ""):
        lc.attrs["band"] = meas.band
    if effects_json is not None:
        lc.attrs["effects"] = effects_json
    if refl_truth is not None:
        lc.attrs["reflection_truth"] = refl_truth
    return (lc, counts) if return_counts else lc
