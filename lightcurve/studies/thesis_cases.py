"""Bernard (2021) ch. 9–10 test cases as data, and the writer of their scenario and shape files.

Every number below is transcribed from the thesis text (``../shared/seeds/004_*.txt``) with its
section; where the text leaves a choice open the constant says which section leaves it open and
the choice is made once here (never per case or per cell).

* Epoch, duration, cadence (§9.3.1): 2020-03-01 08:08:40 UTC, 360 s, one measurement every 5 s.
* Materials (Table 9.2), CubeSat 10 cm, 1.33 kg, facets 0.01 m² (§9.1.2, §9.3.1).
* Orbits: LEO Keplerian elements (§9.3.3), MEO Keplerian elements (§9.3.4), GEO Cartesian state
  (§9.3.5); gravity up to J4 (§4.2.1).
* Sites: Socorro and Bear Lake (Table 9.3) for LEO and MEO; Socorro and Maui (Table 9.4) for
  GEO. One-site cases use Socorro (§9.3.3).
* Initial conditions: 3-2-1 Euler angles (φ about z, θ about y, ψ about x; eq. 3.7) of the
  inertial→body attitude and body rates of every case of §9.3.3–9.3.5, and the ch. 10 LEO
  fast spin with the body frame equal to ECI at the epoch (§10.1).
* Truth dynamics: controlled — ACS error 0.1° (§9.2.3) perturbing the commanded profile
  without accumulating (eq. 7.10); uncontrolled — gravity gradient, SRP and drag in the thesis's
  forms (eq. 4.16–4.23) and process noise sized to 2° (LEO), 10° (MEO), 15° (GEO) of attitude
  error after one orbit (§9.2.4).
* Two-site tasking: the LEO fast spin follows Fig. 9.15 (§9.4.4: Bear Lake 0–260 s, then
  Socorro 300–400 s); the GEO nadir cases follow Fig. 9.16 (§9.4.4: Maui 0–100 and 205–260 s,
  Socorro 105–200 and 300–400 s); ch. 10 cases follow §10.1 (the same switching pattern).
  §9.3.3 says the tasking "will be presented on a case-by-case basis" but gives no other case:
  for every other two-site case (LEO nadir and inertial; all MEO; GEO fast spin and inertial)
  we choose once the §10.1 switching pattern, the pattern the text reports as improving
  two-site results (§9.4.4). Because the tasking of the Monte Carlo tables is not stated, the
  fast-spin cases of Fig. 9.4 and Figs. B.1–B.4 also have tasking-ablation files with the other
  pattern (``pipelines/studies/ablations/scenarios/tasking-<pattern>-*.toml``;
  :data:`ABLATION_TASKING`).
* Scaled MEO/GEO shapes (eq. 9.2): ``A₂ = A₁ (v_r,2ᵀv_r,2)/(v_r,1ᵀv_r,1)``. The text does not
  say at which epoch the two ranges are taken (§9.1.2 leaves it open): we take the mean of
  the squared Socorro range over the one-site window (0–360 s every 5 s) of the LEO fast-spin
  case (v_r,1) and of the MEO / GEO fast-spin case (v_r,2). The mass is "also scaled up"
  (§9.1.2) without a factor: we keep the CubeSat's density (mass × factor^{3/2}, the volume
  ratio). Inertia: uniform solid cube ``m s²/6`` (the text gives mass and size only).

Run ``python -m lightcurve.studies.thesis_cases`` from the repository root to (re)write
``shapes/cube_1u.toml``, ``shapes/cube_meo.toml``, ``shapes/cube_geo.toml`` and every
``pipelines/thesis/*.toml`` and ``pipelines/studies/ablations/scenarios/tasking-*.toml``
this module defines; tests check that the committed files equal this module's output.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["EPOCH_UTC", "DURATION_S", "CADENCE_S", "TABLE_9_2", "ORBITS", "CASES", "Case",
           "scaled_area_factor", "shape_toml", "scenario_toml", "scenario_files", "write_all"]

#: §9.3.1: "the epoch for all of the different test cases was set to 8 hours, 8 minutes, and 40
#: seconds on March 1, 2020, UTC"
EPOCH_UTC = "2020-03-01T08:08:40Z"
#: §9.3.1: "the total measurement time is 360 seconds, with measurements taken every 5 seconds"
DURATION_S = 360.0
CADENCE_S = 5.0
#: §9.2.3: "the error in the control system has a standard deviation of 0.1 degrees"
ACS_SIGMA_DEG = 0.1
#: §9.2.4: process noise "sized to give 2 degrees of error in the attitude state after one
#: orbit" (LEO), 10° (MEO), 15° (GEO)
DRIFT_DEG_PER_ORBIT = {"leo": 2.0, "meo": 10.0, "geo": 15.0}

#: Table 9.2 (axis: ξ, a, m); material key, facet normal
TABLE_9_2 = (
    ("px", (1.0, 0.0, 0.0), 0.1, 0.95, 0.04),
    ("mx", (-1.0, 0.0, 0.0), 0.5, 0.95, 0.08),
    ("py", (0.0, 1.0, 0.0), 0.1, 0.5, 0.5),
    ("my", (0.0, -1.0, 0.0), 0.5, 0.8, 0.5),
    ("pz", (0.0, 0.0, 1.0), 0.1, 0.7, 0.4),
    ("mz", (0.0, 0.0, -1.0), 1.0, 0.95, 0.6),
)
#: §9.1.2: "10cm × 10cm × 10cm, and the mass is 1.33 kg"; §9.3.1: facet area 0.01 m²
CUBESAT_SIDE_M = 0.1
CUBESAT_MASS_KG = 1.33

#: orbit tables (TOML key/values) with their sections
ORBITS = {
    "leo": ("§9.3.3", {"type": "keplerian", "a_km": 6871.14, "e": 0.01, "i_deg": 83.0,
                       "raan_deg": 0.0, "argp_deg": 0.0, "nu_deg": 126.264, "gravity": "J4"}),
    "meo": ("§9.3.4", {"type": "keplerian", "a_km": 26378.14, "e": 0.0, "i_deg": 89.0,
                       "raan_deg": 179.0, "argp_deg": 0.0, "nu_deg": 39.511, "gravity": "J4"}),
    # §9.3.5 prints the velocity as "r^I" (a typo for v^I)
    "geo": ("§9.3.5", {"type": "cartesian", "r_km": [-35529.95, 23098.15, 68.34],
                       "v_km_s": [-1.672, -2.571, 0.0032], "gravity": "J4"}),
}
#: one site (§9.3.3: "Socorro, NM, was the only observatory") and the second site per regime
#: (Table 9.3: Bear Lake for LEO and MEO; Table 9.4: Maui for GEO)
SECOND_SITE = {"leo": "bear_lake", "meo": "bear_lake", "geo": "maui"}

#: two-site taskings: (first site windows, second site windows), seconds after the epoch
TASKING = {
    # Fig. 9.15 (§9.4.4): "the BLO first observed the spacecraft from 0 to 260 seconds, with
    # follow-on observations from Socorro, NM, from 300 to 400 seconds"
    "fig9-15": ([[300.0, 400.0]], [[0.0, 260.0]],
                "Fig. 9.15 (§9.4.4): Bear Lake 0-260 s, then Socorro 300-400 s"),
    # Fig. 9.16 (§9.4.4) and §10.1: Socorro 105-200 and 300-400 s, the other site 0-100 and
    # 205-260 s
    "switching": ([[105.0, 200.0], [300.0, 400.0]], [[0.0, 100.0], [205.0, 260.0]],
                  "Socorro 105-200 and 300-400 s, second site 0-100 and 205-260 s"),
}


@dataclass(frozen=True)
class Case:
    """One initial condition of ch. 9–10 (the files add dynamics, sites and shape)."""

    stem: str               # file-name stem before -{shape}-{dynamics}-{n}site
    regime: str             # "leo" | "meo" | "geo"
    euler321_deg: tuple     # (φ, θ, ψ), inertial→body, eq. 3.7
    omega_deg_s: tuple      # body axes
    source: str             # where the text gives the values
    dynamics: tuple = ("controlled", "uncontrolled")
    tasking: str = "switching"
    tasking_source: str = ("§9.3.3 leaves the two-site tasking of this case open; chosen once "
                           "for every such case: the §10.1 switching pattern")
    reflection: bool = False  # ch. 10: truth reflection parameters perturbed (§10.1)


_LEO_FAST = ((-42.4122, 59.1601, 48.9897), (2.0, 1.0, 3.6))
_LEO_NADIR = ((-174.911, 35.9513, 8.6586), (0.0, 0.0635, 0.0))
_MEO_FAST = ((-8.8009, 24.7231, 92.7882), (2.0, 1.0, 3.6))
_MEO_IC1 = ((-1.2134, -50.4784, 1.5715), (0.0, 0.0084, 0.0))
_MEO_IC2 = ((0.8236, 39.5038, 1.2961), (0.0, 0.0084, 0.0))
_GEO_FAST = ((-27.2326, 1.1295, -0.050061), (2.0, 1.0, 3.6))
_GEO_IC1 = ((-123.03, -0.05969, 89.908), (0.0, 0.0041465, 0.0))
_GEO_IC2 = ((-33.028, 0.092397, 89.94), (0.0, 0.0041465, 0.0))
_GEO_IC3 = ((56.972, 0.05969, 0.092397), (0.0, 0.0, 0.0041465))
_ZERO = (0.0, 0.0, 0.0)
_CTRL = ("controlled",)
_FIG916 = "Fig. 9.16 (§9.4.4)"
_S101 = "§10.1 (every two-site case of ch. 10)"

CASES = (
    # ---- LEO (§9.3.3) -------------------------------------------------------------------
    Case("leo-ic1-fast-spin", "leo", *_LEO_FAST,
         "§9.3.3: +X bisector toward Socorro, +Z near the orbit normal",
         tasking="fig9-15", tasking_source="Fig. 9.15 (§9.4.4)"),
    Case("leo-ic2-nadir", "leo", *_LEO_NADIR,
         "§9.3.3: +Z along r (-Z nadir), +Y along the orbit normal; orbit rate about +Y"),
    Case("leo-liic1-inertial", "leo", _LEO_FAST[0], _ZERO,
         "§9.3.3 LIIC1: the fast-spin attitude, zero rate", dynamics=_CTRL),
    Case("leo-liic2-inertial", "leo", _LEO_NADIR[0], _ZERO,
         "§9.3.3 LIIC2: the nadir attitude, zero rate", dynamics=_CTRL),
    Case("leo-liic3-inertial", "leo", _ZERO, _ZERO,
         "§9.3.3 LIIC3: body frame = ECI at the epoch, zero rate", dynamics=_CTRL),
    # ---- ch. 10 (§10.1): LEO fast spin from body = ECI, LEO inertial LIIC1, GEO nadir IC2 ----
    Case("leo-ch10-fast-spin-eci", "leo", _ZERO, _LEO_FAST[1],
         "§10.1: body frame aligned with ECI at the epoch, the fast-spin rates",
         dynamics=_CTRL, tasking_source=_S101, reflection=True),
    Case("leo-ch10-liic1-inertial", "leo", _LEO_FAST[0], _ZERO,
         "§10.1: the inertially fixed LEO case with LIIC1", dynamics=_CTRL,
         tasking_source=_S101, reflection=True),
    # ---- MEO (§9.3.4) -------------------------------------------------------------------
    Case("meo-fast-spin", "meo", *_MEO_FAST,
         "§9.3.4: +X along the Socorro/Sun bisector, -Z near the orbit normal"),
    Case("meo-ic1-nadir", "meo", *_MEO_IC1,
         "§9.3.4 MEO IC1: +Z along r, +Y cross-track; orbit rate about +Y"),
    Case("meo-ic2-nadir", "meo", *_MEO_IC2,
         "§9.3.4 MEO IC2: +X nadir, +Y cross-track; orbit rate about +Y"),
    # §9.3.4 prints ω = [1.473e-7, 0.0084, 0.000147] deg/s; the stated direction (the orbit
    # normal in ECI = body axes, [sin i sin Ω, −sin i cos Ω, cos i] × n) gives 1.47e-4 for the
    # first component: the file keeps the printed value (a 0.05° difference over 360 s).
    Case("meo-ic3-slow", "meo", _ZERO, (1.473e-7, 0.0084, 0.000147),
         "§9.3.4 MEO IC3: body = ECI, rate of the mean motion about the orbit normal"),
    Case("meo-inertial-ic1", "meo", _MEO_FAST[0], _ZERO,
         "§9.3.4 inertial set 1: the fast-spin attitude, zero rate", dynamics=_CTRL),
    Case("meo-inertial-ic2", "meo", _ZERO, _ZERO,
         "§9.3.4 inertial set 2: body = ECI, zero rate", dynamics=_CTRL),
    Case("meo-inertial-ic3", "meo", _MEO_IC1[0], _ZERO,
         "§9.3.4 inertial set 3: the MEO IC1 attitude, zero rate", dynamics=_CTRL),
    # ---- GEO (§9.3.5) -------------------------------------------------------------------
    Case("geo-fast-spin", "geo", *_GEO_FAST,
         "§9.3.5: +X along the Socorro/Sun bisector, +Z near the orbit normal"),
    Case("geo-ic1-nadir", "geo", *_GEO_IC1,
         "§9.3.5 GEO IC1: +Z along r, +Y cross-track; orbit rate about +Y",
         tasking_source=_FIG916),
    Case("geo-ic2-nadir", "geo", *_GEO_IC2,
         "§9.3.5 GEO IC2: +X nadir, +Y cross-track; orbit rate about +Y",
         tasking_source=_FIG916),
    Case("geo-ic3-nadir", "geo", *_GEO_IC3,
         "§9.3.5 GEO IC3: +Y along r, +Z cross-track; orbit rate about +Z",
         tasking_source=_FIG916),
    Case("geo-inertial-ic1", "geo", _GEO_FAST[0], _ZERO,
         "§9.3.5 inertial set 1: the fast-spin attitude, zero rate", dynamics=_CTRL),
    Case("geo-inertial-ic2", "geo", _GEO_IC2[0], _ZERO,
         "§9.3.5 inertial set 2: the GEO IC2 attitude, zero rate", dynamics=_CTRL),
    Case("geo-inertial-ic3", "geo", _ZERO, _ZERO,
         "§9.3.5 inertial set 3: body = ECI, zero rate", dynamics=_CTRL),
    Case("geo-ch10-ic2-nadir", "geo", *_GEO_IC2,
         "§10.1: the nadir-pointing GEO case with GEO IC2", dynamics=_CTRL,
         tasking_source=_S101, reflection=True),
)

#: shapes per regime: LEO the CubeSat only; MEO and GEO the CubeSat and the eq. 9.2 scaled cube
#: (§9.3.1, §9.3.4, §9.3.5). Ch. 10's GEO case: §10.1 does not say which GEO shape; chosen once:
#: the scaled one (the shape of the GEO IC2 results of Figs. 9.11 and 9.17).
SHAPES = {"leo": (("", "cube_1u"),), "meo": (("cubesat", "cube_1u"), ("scaled", "cube_meo")),
          "geo": (("cubesat", "cube_1u"), ("scaled", "cube_geo"))}
_CH10_SHAPES = {"geo-ch10-ic2-nadir": (("", "cube_geo"),)}


def _fmt(v) -> str:
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, float) else str(v)


# --------------------------------------------------------------------------------------------
# eq. 9.2 scaled shapes
# --------------------------------------------------------------------------------------------
def _mean_sq_range_m2(regime: str) -> float:
    """Mean |v_r|² (m²) from Socorro over the one-site window (0–360 s every 5 s)."""
    from ..geometry.observation import compute_geometry
    from ..geometry.orbits import orbit_from_section
    from ..geometry.sites import get_site

    orb = orbit_from_section(dict(ORBITS[regime][1]))
    t = np.arange(0.0, DURATION_S + 1e-9, CADENCE_S)
    r, v = orb.positions(EPOCH_UTC, t)
    g = compute_geometry(EPOCH_UTC, t, np.zeros(t.size, int), [get_site("socorro")], r, v)
    return float(np.mean(g.range_obs_m ** 2))


def scaled_area_factor(regime: str) -> float:
    """Bernard eq. 9.2 area factor ``v_r,2ᵀv_r,2 / v_r,1ᵀv_r,1`` of the MEO or GEO cube (module
    docstring: mean squared Socorro ranges over the one-site window)."""
    return _mean_sq_range_m2(regime) / _mean_sq_range_m2("leo")


def shape_toml(name: str, factor: float = 1.0, regime: str = "leo") -> str:
    """TOML text of the CubeSat (factor 1) or of an eq. 9.2 scaled cube (``factor`` on areas)."""
    side = float(CUBESAT_SIDE_M * np.sqrt(factor))
    area = side * side
    mass = float(CUBESAT_MASS_KG * factor ** 1.5)
    inertia = float(mass * side * side / 6.0)
    if factor == 1.0:
        head = [f"# {name}: the 1U CubeSat of Bernard (2021): 10 cm cube, 1.33 kg (§9.1.2), six "
                "0.01 m^2 facets (§9.3.1),",
                "# the reflection parameters of Table 9.2 (Cook-Torrance: xi = specular/diffuse "
                "weighting, a = diffuse",
                "# albedo = F0, m = microfacet slope). Used for LEO, and as the 'CubeSat' MEO/GEO "
                "shape (§9.3.1).",
                "# Inertia: uniform solid cube m s^2/6 (§9.1.2 gives only mass and size).",
                "# -Z is fully diffuse (xi = 1, on its bound): the §10.1 truth draw and Model 3 "
                "hold it fixed",
                "# (lightcurve.studies.fit_reflection.perturb_reflection, "
                "lightcurve.filters.facet_states)."]
        desc = "1U CubeSat, 10 cm, 1.33 kg, Table 9.2 materials (Bernard 2021)"
    else:
        head = [f"# {name}: the 1U CubeSat scaled for {regime.upper()} by Bernard (2021) eq. 9.2, "
                "A2 = A1 (v_r2.v_r2)/(v_r1.v_r1).",
                f"# Factor {factor:.4f}: the mean squared Socorro range over the one-site window "
                "(0-360 s every 5 s)",
                f"# of the {regime.upper()} fast-spin case over that of the LEO fast-spin case "
                "(§9.1.2 leaves the epoch of",
                "# the ranges open; lightcurve.studies.thesis_cases). Side "
                f"{side:.6f} m. Mass scaled at the CubeSat's density",
                "# (factor^1.5; §9.1.2 says the mass is 'also scaled up' without a factor). "
                "Inertia: uniform solid cube.",
                "# Materials: Table 9.2 (§9.3.1: all test cases use them)."]
        desc = f"1U CubeSat scaled for {regime.upper()} (eq. 9.2, area x {factor:.4f}), Table 9.2"
    lines = head + ["", "[shape]", f'name = "{name}"', f'description = "{desc}"',
                    f"mass_kg = {mass!r}", "# uniform solid cube: I = m s^2 / 6 (kg m^2)",
                    f"inertia_diag_kg_m2 = [{inertia!r}, {inertia!r}, {inertia!r}]", ""]
    for key, n, xi, a, m in TABLE_9_2:
        axis = ("+" if sum(n) > 0 else "-") + "XYZ"[int(np.argmax(np.abs(n)))]
        lines += [f"[materials.{key}]   # Table 9.2, {axis}", 'brdf = "cook_torrance"',
                  f"xi = {xi!r}", f"a = {a!r}", f"m = {m!r}", ""]
    for key, n, *_ in TABLE_9_2:
        c = [0.5 * side * x for x in n]
        lines += ["[[facets]]", f"normal = {_fmt([float(x) for x in n])}", f"area_m2 = {area!r}",
                  f"center_m = {_fmt([float(x) + 0.0 for x in c])}", f'material = "{key}"', ""]
    return "\n".join(lines).rstrip() + "\n"


# --------------------------------------------------------------------------------------------
# scenarios
# --------------------------------------------------------------------------------------------
def _shapes_of(case: Case):
    return _CH10_SHAPES.get(case.stem, SHAPES[case.regime])


def scenario_name(case: Case, shape_tag: str, dynamics: str, nsites: int) -> str:
    """File stem: ``<case>[-<shape>]-<dynamics>-<n>site``."""
    parts = [case.stem] + ([shape_tag] if shape_tag else []) + [dynamics, f"{nsites}site"]
    return "-".join(parts)


def scenario_toml(case: Case, shape_tag: str, shape: str, dynamics: str, nsites: int,
                  tasking: str | None = None) -> str:
    """The scenario TOML text of one case, shape, dynamics and site count.

    ``tasking`` (a :data:`TASKING` key, two sites only) replaces the case's own tasking: the
    file is then a tasking ablation (:func:`ablation_scenario_files`); its scenario name has
    the suffix ``-tasking-<tasking>``."""
    name = scenario_name(case, shape_tag, dynamics, nsites)
    if tasking is not None:
        if nsites != 2 or tasking not in TASKING:
            raise ValueError(f"a tasking ablation needs two sites and one of {sorted(TASKING)}")
        name += f"-tasking-{tasking}"
    osrc, orbit = ORBITS[case.regime]
    second = SECOND_SITE[case.regime]
    ch = "ch. 10" if case.reflection else "ch. 9"
    lines = [f"# Bernard (2021) {ch} test case: {case.source}.",
             f"# {case.regime.upper()} orbit {osrc}; epoch, 5 s cadence §9.3.1; {dynamics} truth "
             f"({'eq. 7.8-7.11, ACS 0.1 deg §9.2.3' if dynamics == 'controlled' else 'eq. 4.12-4.23, §9.2.4 process noise'});",
             f"# shape {shape} ({'Table 9.2 CubeSat' if shape == 'cube_1u' else 'eq. 9.2 scaled cube'}).",
             "# Written by lightcurve.studies.thesis_cases (python -m lightcurve.studies.thesis_cases); "
             "edit there.", ""]
    dur = DURATION_S if nsites == 1 else 400.0
    lines += ["[scenario]", f'name = "{name}"',
              f'epoch_utc = "{EPOCH_UTC}"   # §9.3.1',
              f"duration_s = {dur!r}   # §9.3.1: 360 s; two-site windows run to 400 s (§9.4.4, §10.1)",
              f"cadence_s = {CADENCE_S!r}   # §9.3.1", "seed = 1", "",
              f"[orbit]   # {osrc}; gravity up to J4 (§4.2.1)"]
    lines += [f"{k} = {_fmt(v)}" for k, v in orbit.items()]
    lines += ["", "[shape]", f'name = "{shape}"', "", "[attitude]",
              f'dynamics = "{dynamics}"', 'frame = "inertial"',
              f"euler321_deg = {_fmt([float(x) for x in case.euler321_deg])}   # {case.source.split(':')[0]}, 3-2-1 (eq. 3.7)",
              f"omega_deg_s = {_fmt([float(x) for x in case.omega_deg_s])}   # body axes"]
    if dynamics == "controlled":
        lines += [f"acs_sigma_deg = {ACS_SIGMA_DEG!r}   # §9.2.3",
                  'acs_mode = "jitter"   # eq. 7.10: perturbs the commanded attitude, no accumulation']
    else:
        lines += ['torques = ["gravity_gradient", "srp", "drag"]   # §4.2.2-4.2.4',
                  'torque_forms = "thesis"   # eq. 4.16-4.21 as written (R_d = xi, R_s = 1 - xi; drag along n)',
                  f"drift_deg_per_orbit = {DRIFT_DEG_PER_ORBIT[case.regime]!r}   # §9.2.4"]
    lines.append("")
    if nsites == 1:
        lines += ["[[sites]]   # §9.3.3: one-site cases use Socorro", 'name = "socorro"',
                  f"windows_s = [[0.0, {DURATION_S!r}]]", ""]
    else:
        w1, w2, txt = TASKING[tasking or case.tasking]
        src = case.tasking_source
        if tasking is not None:
            txt = (f"{second} {_windows_text(w2)}, socorro {_windows_text(w1)} "
                   f"({_PATTERN[tasking]})")
            src = (f"ABLATION of {scenario_name(case, shape_tag, dynamics, nsites)}.toml "
                   f"(its tasking: {TASKING[case.tasking][2]}; source: {case.tasking_source}); "
                   "§9.3.3 leaves the Monte Carlo tables' tasking open")
        lines += [f"# two-site tasking: {txt}; source: {src}",
                  "[[sites]]", 'name = "socorro"', f"windows_s = {_fmt(w1)}", "",
                  "[[sites]]", f'name = "{second}"', f"windows_s = {_fmt(w2)}", ""]
    eclipse = ("the LEO object is in the Earth's umbra at the epoch; the thesis's measurement "
               "model (ch. 5) has no shadow term" if case.regime == "leo"
               else "the thesis's measurement model (ch. 5) has no shadow term")
    lines += ["[measurement]", "r_percent = 1.0   # §9.2.2 (studies override: 1 % and 10 %)",
              f"ignore_eclipse = true   # {eclipse}", ""]
    if case.reflection:
        lines += ["[reflection]   # §10.1: truth parameters p + N(0, (0.1 p)^2); xi on a bound "
                  "(-Z, xi = 1) held fixed",
                  "perturb = true", "sigma_frac = 0.1", 'params = ["xi", "a", "m", "A"]', ""]
    return "\n".join(lines).rstrip() + "\n"


def scenario_files() -> dict:
    """``{file name: TOML text}`` of every thesis scenario (pipelines/thesis)."""
    out = {}
    for case in CASES:
        for tag, shape in _shapes_of(case):
            for dyn in case.dynamics:
                for ns in (1, 2):
                    out[scenario_name(case, tag, dyn, ns) + ".toml"] = \
                        scenario_toml(case, tag, shape, dyn, ns)
    return out


_PATTERN = {"fig9-15": "the pattern of Fig. 9.15, §9.4.4",
            "switching": "the switching pattern of Fig. 9.16 and §10.1"}


def _windows_text(w) -> str:
    return " and ".join(f"{a:g}-{b:g}" for a, b in w) + " s"


#: tasking ablations: the fast-spin cases of Fig. 9.4 and Figs. B.1–B.4 with the other
#: tasking of :data:`TASKING` (the tasking of their Monte Carlo tables is not stated, §9.3.3)
ABLATION_TASKING = {"leo-ic1-fast-spin": "switching", "meo-fast-spin": "fig9-15",
                    "geo-fast-spin": "fig9-15"}


def ablation_scenario_files() -> dict:
    """``{file name: TOML text}`` of the tasking ablations (pipelines/studies/ablations/scenarios,
    ``tasking-<pattern>-<base stem>.toml``): every two-site scenario of the cases in
    :data:`ABLATION_TASKING` with the other tasking."""
    out = {}
    for case in CASES:
        tk = ABLATION_TASKING.get(case.stem)
        if tk is None:
            continue
        if tk == case.tasking:
            raise ValueError(f"{case.stem}: the ablation tasking is the case's own")
        for tag, shape in _shapes_of(case):
            for dyn in case.dynamics:
                out[f"tasking-{tk}-" + scenario_name(case, tag, dyn, 2) + ".toml"] = \
                    scenario_toml(case, tag, shape, dyn, 2, tasking=tk)
    return out


def shape_files() -> dict:
    """``{file name: TOML text}`` of the CubeSat and the two eq. 9.2 scaled cubes (shapes/)."""
    return {"cube_1u.toml": shape_toml("cube_1u"),
            "cube_meo.toml": shape_toml("cube_meo", scaled_area_factor("meo"), "meo"),
            "cube_geo.toml": shape_toml("cube_geo", scaled_area_factor("geo"), "geo")}


def write_all(root=".") -> list:
    """Write :func:`shape_files` into ``root/shapes``, :func:`scenario_files` into
    ``root/pipelines/thesis`` and :func:`ablation_scenario_files` into
    ``root/pipelines/studies/ablations/scenarios``; returns the written paths."""
    from ..io.atomic import atomic_write_text

    root = Path(root)
    written = []
    for folder, files in (("shapes", shape_files()), ("pipelines/thesis", scenario_files()),
                          ("pipelines/studies/ablations/scenarios", ablation_scenario_files())):
        d = root / folder
        d.mkdir(parents=True, exist_ok=True)
        for name, text in files.items():
            atomic_write_text(d / name, text)
            written.append(d / name)
    return written


if __name__ == "__main__":  # pragma: no cover - maintenance entry point
    import sys

    for p in write_all(sys.argv[1] if len(sys.argv) > 1 else "."):
        print(p)
