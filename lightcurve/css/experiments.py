"""O'Keefe (2015) ch. 3 simulation set-up as the text gives it (values and citations in
:mod:`lightcurve.css.okeefe2015`): sensor sets, dispersions, estimator tuning and the
:class:`~lightcurve.css.truth.CSSScenario` of one experiment case.

``variant="thesis"`` runs the estimators and controller of the text (:mod:`.sunline_thesis`,
eq. 3.64 with its integral term, single-point methods without an activity threshold);
``variant="robust"`` runs ours on the same simulated spacecraft (the albedo-aware sun-line
filters of :mod:`.sunline_ekf`, which use the known orbit and a built-in albedo model, and the
controller of :mod:`.control`).
"""

from __future__ import annotations

import numpy as np

from . import okeefe2015 as ok
from .configurations import CUBE_AZEL_DEG, DUAL_PYRAMID_AZEL_DEG, from_azel_deg
from .control import ControlParams
from .gyro import GyroSpec, gyro_grade
from .sunline_thesis import thesis_params
from .truth import CSSScenario, Dispersions

__all__ = ["TOMS_ALBEDO_GRIDS", "thesis_css", "thesis_dispersions", "thesis_filter_params",
           "thesis_scenario", "thesis_albedo"]


def thesis_css(configuration: str, fov_half_angle_deg: float | None = None):
    """The nominal sensor set of §2.2 with the 60° FOV half angle (§2.1.3 "120° edge-to-edge")
    and, for the dual pyramid, the structure horizon of §2.2.1 (fields of view "clipped at the
    local-horizontal plane": +z for sensors 1-4 on the +z face, −z for sensors 5-8)."""
    fov = ok.CSS_SIM["fov_half_angle_deg"] if fov_half_angle_deg is None else fov_half_angle_deg
    if configuration in ("dual_pyramid", "pyramid"):
        hor = np.zeros((8, 3))
        hor[:4, 2] = 1.0
        hor[4:, 2] = -1.0
        return from_azel_deg(DUAL_PYRAMID_AZEL_DEG, fov, name="dual_pyramid",
                             horizon_normals=hor)
    if configuration == "cube":
        return from_azel_deg(CUBE_AZEL_DEG, fov, name="cube")
    raise ValueError(f"unknown thesis configuration {configuration!r}; allowed: dual_pyramid, cube")


def thesis_dispersions(**override) -> Dispersions:
    """§2.4 dispersions (okeefe2015.CSS_SIM; keys of CSS_SIM override them)."""
    c = {**ok.CSS_SIM, **override}
    return Dispersions(rate_max_deg_s=c["initial_rate_max_deg_s"],
                       css_scale_common_max=c["scale_common_max"],
                       css_scale_sigma=c["scale_individual_sigma"],
                       css_misalignment_sigma_deg=c["misalignment_sigma_deg"],
                       css_noise_sigma=c["noise_sigma"])


def _grade_name(gyro):
    if gyro is None:
        return None
    return gyro.name if isinstance(gyro, GyroSpec) else str(gyro)


def thesis_filter_params(estimator: str, gyro) -> np.ndarray:
    """Parameter array of the thesis EKF/ECKF (§3.3) for a Table 2.3 grade name (None:
    gyro-less, §3.3.3: σ_ω = σ_ωβ = 0, σ_s = 1 rad/√s)."""
    name = _grade_name(gyro)
    if name is None:
        sw = sr = sd = 0.0
        grade = "intermediate"
    else:
        spec = gyro_grade(name) if not isinstance(gyro, GyroSpec) else gyro
        sw, sr, sd = spec.arw, spec.bias_sigma, spec.rrw
        grade = name if name in ok.GYRO_TABLE_2_3 else "intermediate"
    shadow = ok.EKF_TUNING["shadow_level"]
    sfrac = ok.EKF_TUNING["shadow_fraction"]
    if estimator == "ekf":
        e = ok.EKF_TUNING
        return thesis_params("ekf", sigma_v=e["sigma_v"], sigma_s=e["sigma_s"][grade],
                             sigma_w=sw, sigma_wd=sd, sigma_wr=sr,
                             strong_frac=e["strong_fraction"],
                             strong_factor=e["strong_sigma_factor"], shadow_level=shadow,
                             shadow_frac=sfrac)
    e = ok.ECKF_TUNING
    return thesis_params("eckf", sigma_v=e["sigma_v"], sigma_s=e["sigma_s"], sigma_w=sw,
                         sigma_wd=sd, sigma_wr=sr,
                         strong_frac=ok.EKF_TUNING["strong_fraction"],
                         strong_factor=ok.EKF_TUNING["strong_sigma_factor"],
                         shadow_level=shadow, shadow_frac=sfrac,
                         cons_sigmas=e["consistency_sigmas"],
                         sigma_mis=np.radians(e["sigma_misalignment_deg"]),
                         sigma_valpha=e["sigma_v_alpha"], sigma_ck=e["sigma_c_kappa"],
                         sigma_d_dot=e["sigma_d_dot"])


_TOMS_CACHE: dict = {}
TOMS_ALBEDO_GRIDS = {"toms": "1p25x1", "toms5": "5x5", "toms10": "10x10"}
"""Truth-albedo names of the §2.1.2.1 TOMS grids (1°×1.25°, 5°×5°, 10°×10°)."""


def thesis_albedo(grid: str = "1p25x1", required: bool = False):
    """The truth albedo of §2.1.2.1: TOMS mean and standard deviation (drawn per run).  When
    the data folder is absent: with ``required`` the :class:`~lightcurve.errors.InputError`
    naming it is raised, otherwise a RuntimeWarning says so and None (the built-in zonal
    model) is returned."""
    import warnings

    from ..errors import InputError
    from .albedo import load_toms

    if grid not in _TOMS_CACHE:
        try:
            _TOMS_CACHE[grid] = load_toms(grid)
        except InputError as e:
            if required:
                raise
            warnings.warn(f"TOMS albedo grid {grid} not available ({e}); the truth uses the "
                          "built-in 10° zonal albedo instead", RuntimeWarning, stacklevel=2)
            _TOMS_CACHE[grid] = None
    return _TOMS_CACHE[grid]


def thesis_scenario(configuration="dual_pyramid", estimator="ekf", *, variant="thesis",
                    gyro="intermediate", controlled=False, duration_s=None, albedo="toms",
                    perturbations=True, sim=None, **kw) -> CSSScenario:
    """The §2.4 / ch. 3 simulation of one case.  ``gyro``: a Table 2.3 grade name or None;
    ``albedo``: "toms" (TOMS 1°×1.25° with its spread, §2.1.2.1; "toms5", "toms10" the
    coarser grids, :data:`TOMS_ALBEDO_GRIDS`), "builtin", "none", an
    AlbedoMap or a (mean, std) pair; ``sim``: overrides of the §2.4 values (keys
    altitude_km, inclination_deg, raan_deg, epoch_utc, perturbations, css_rate_hz,
    gyro_rate_hz, shadow_model (truth Earth shadow, default the binary one of eq. 2.21) and the
    CSS_SIM keys); extra keywords go to :class:`CSSScenario`."""
    sim = dict(sim or {})
    orb = {**ok.ORBIT}
    for k in ("inclination_deg", "raan_deg", "epoch_utc"):
        if k in sim:
            orb[k] = sim.pop(k)
    if "altitude_km" in sim:
        orb["altitude_m"] = 1e3 * float(sim.pop("altitude_km"))
    perturbations = bool(sim.pop("perturbations", perturbations))
    rates = {k: float(sim.pop(k, ok.CSS_SIM[k])) for k in ("css_rate_hz", "gyro_rate_hz")}
    shadow_model = str(sim.pop("shadow_model", ok.TRUTH_SHADOW_MODEL))
    unknown = set(sim) - set(ok.CSS_SIM)
    if unknown:
        raise ValueError(f"unknown simulation keys: {', '.join(sorted(unknown))}")
    css = thesis_css(configuration, sim.get("fov_half_angle_deg"))
    if isinstance(albedo, str) and albedo in TOMS_ALBEDO_GRIDS:
        alb = thesis_albedo(TOMS_ALBEDO_GRIDS[albedo])
    elif albedo == "builtin":
        alb = None
    elif albedo == "none":
        alb = False
    else:
        alb = albedo
    c = ok.CONTROL
    gl = ok.GYROLESS
    tp = thesis_filter_params(estimator, gyro) if estimator in ("ekf", "eckf") else None
    if tp is None:
        tp = thesis_filter_params("ekf", gyro)   # shadow level etc. for the single-point path
    return CSSScenario(
        css, estimator=estimator, gyro=gyro, controlled=controlled,
        duration_s=ok.ORBIT["duration_s"] if duration_s is None else float(duration_s),
        dt_s=1.0 / rates["css_rate_hz"],
        substeps=max(1, int(round(rates["gyro_rate_hz"] / rates["css_rate_hz"]))),
        epoch_utc=orb["epoch_utc"], altitude_m=orb["altitude_m"],
        inclination_deg=orb["inclination_deg"], raan_deg=orb["raan_deg"],
        perturbations=perturbations, dispersions=thesis_dispersions(**sim), albedo=alb,
        start_sunlit=False, variant=variant, thesis_params=tp,
        thesis_control=(c["k_gain"], c["p_gain"], c["ki_gain"], float(np.radians(c["deadband_deg"]))),
        control=ControlParams(axis=c["axis"]), noise_in_scale=True,
        shadow_model=shadow_model,
        gyroless={"rate_limit_deg_s": gl["rate_limit_deg_s"], "lowpass_hz": gl["lowpass_hz"],
                  "sigma_s": gl["sigma_s"]}, **kw)
