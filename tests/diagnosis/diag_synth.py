"""Concealed-effect cases for the diagnosis proofs (tests and benchmarks/diagnosis_confusion.py).

Each case simulates one of the scenarios in ``pipelines/diagnosis/`` with one effect switched
on at random realistic parameters (the effect's own ``sample_params``, fixed seed), then
diagnoses the lightcurve with the same scenario *without* the effect (attitude = the file's
truth, nothing free). Scenario choice per effect (where the effect is physically observable):

* ``diag-leo-lit-2site``: lit two-site LEO pass, elevations 5–73°: extinction, zero_point,
  unmodelled_facet, specular_glint, and the no-effect case. (Earthshine is NOT observable
  there: seen from a dark site, the LEO object sees almost no sunlit Earth, Δm < 1e-5 mag;
  the case ``earthshine@lit`` keeps that negative result runnable.)
* ``diag-meo-dusk-2site``: a box-wing at 12,000 km seen after dusk at solar phase 155° → 70°:
  its observer-facing side faces a gibbous sunlit Earth and is barely sunlit: earthshine
  (truth on a 5° grid of the built-in albedo map; the diagnosis model uses its default 10°
  grid — the two differ by < 0.005 mag here), and the no-effect case ``none@meo``;
* ``diag-leo-lit-2site-mesh``: the lit LEO pass with the box-wing as a mesh: self_shadowing
  (truth ray-cast with 96×96 samples per triangle, the diagnosis model with 48×48 —
  the effect has no fitted parameter, so seeds differ by noise and ACS jitter only), and the
  no-effect case ``none@mesh``;
* ``diag-leo-shadow-2site``: the pass ends with the object entering the Earth's shadow:
  penumbra;
* ``diag-geo-fast-1site``: a fast-tumbling GEO box-wing (light time 0.12 s, flashes of
  several mag/s): light_time, clock_offset, exposure_smearing.

Conditioning (stated deviation from plain prior draws): an unmodelled facet or glint of
random orientation on a tumbling body may never face both the Sun and the observer during
the pass — then nothing is concealed. Their normal is drawn as the body-frame Sun–observer
bisector at a random epoch of the pass, turned by a random angle up to 5°; area (and glint
exponent) come from ``sample_params``.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from lightcurve._paths import data_dir

SCEN = {
    "lit": "diag-leo-lit-2site.toml",
    "shadow": "diag-leo-shadow-2site.toml",
    "geo": "diag-geo-fast-1site.toml",
    "meo": "diag-meo-dusk-2site.toml",
    "mesh": "diag-leo-lit-2site-mesh.toml",
}
#: case name → scenario key. A case is an effect name, "none", or "<effect>@<scenario key>"
#: for an effect (or none) in another than its proof scenario.
CASE_SCENARIO = {"none": "lit", "extinction": "lit", "zero_point": "lit",
                 "unmodelled_facet": "lit", "specular_glint": "lit", "penumbra": "shadow",
                 "light_time": "geo", "clock_offset": "geo", "exposure_smearing": "geo",
                 "earthshine": "meo", "none@meo": "meo", "self_shadowing": "mesh",
                 "none@mesh": "mesh"}
#: cases run by default (benchmarks/diagnosis_confusion.py without --effects)
DEFAULT_CASES = list(CASE_SCENARIO)
#: options of the TRUTH effect (the diagnosis proposes the registry defaults)
TRUTH_OPTIONS = {"earthshine": {"resolution_deg": 5.0}, "self_shadowing": {"subdivisions": 96}}


def case_effect(case):
    """(effect name or "none", scenario key) of a case name."""
    if "@" in case:
        eff, key = case.split("@", 1)
        return eff, key
    return case, CASE_SCENARIO[case]

_CACHE: dict = {}


def scenario(key):
    from lightcurve.studies.scenario import load_scenario

    if key not in _CACHE:
        _CACHE[key] = load_scenario(data_dir("pipelines") / "diagnosis" / SCEN[key])
    return _CACHE[key]


class _Sizes:
    def __init__(self, n_sites):
        self.n_sites = n_sites
        self.n_sensors = None


def _bisector_normal(lc, rng):
    from lightcurve.rotations import quat_rotate

    k = int(rng.integers(len(lc)))
    h = lc.obj_to_sun_unit[k] + lc.obj_to_obs_unit[k]
    h = quat_rotate(lc.truth_q[k], h / np.linalg.norm(h))
    # turn by a random angle up to 5 deg about a random perpendicular axis
    a = rng.normal(size=3)
    a -= a.dot(h) * h
    a /= np.linalg.norm(a)
    ang = np.radians(rng.uniform(0.0, 5.0))
    n = h * np.cos(ang) + np.cross(a, h) * np.sin(ang)
    return float(np.degrees(np.arctan2(n[1], n[0]))), float(np.degrees(np.arcsin(np.clip(n[2], -1, 1))))


def case_params(effect, seed):
    """(scenario, effects table for the TOML-like dict, the true parameters)."""
    from lightcurve.physics import get_effect
    from lightcurve.studies.simulate import simulate

    effect, key = case_effect(effect)
    sc = scenario(key)
    if effect == "none":
        return sc, {}, {}
    rng = np.random.default_rng(1000 + seed)
    names = [s.site.id for s in sc.sites]
    p = get_effect(effect).sample_params(rng, _Sizes(len(names)))
    if effect in ("unmodelled_facet", "specular_glint"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lc0 = simulate(sc, seed=seed)
        p["az_deg"], p["el_deg"] = _bisector_normal(lc0, rng)
    table = {k: ({s: float(x) for s, x in zip(names, v)} if np.ndim(v) else float(v)) for k, v in p.items()}
    table.update(TRUTH_OPTIONS.get(effect, {}))
    return sc, {effect: table}, p


def run_case(effect, seed, **diag_kw):
    """Simulate with ``effect`` concealed and diagnose without it; a summary dict."""
    from lightcurve.diagnosis.diagnose import diagnose
    from lightcurve.diagnosis.problem import magnitude_problem
    from lightcurve.studies.simulate import simulate

    sc, table, p = case_params(effect, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc = simulate(replace(sc, effects=table), seed=seed)
    prob = magnitude_problem(lc, sc.shape, free=[], label=f"{effect}-{seed}")
    d = diagnose(prob, **diag_kw)
    js = d.summary()
    ranked = [c["name"] for c in js["candidates"] if c.get("applicable")]
    return {"effect": effect, "seed": seed, "n": js["n"], "verdict": js["verdict"],
            "top": ranked[0] if ranked else None, "chosen": js["chosen"],
            "baseline_chi2_dof": js["baseline"]["chi2_dof"], "final_chi2_dof": js["final"]["chi2_dof"],
            "final_consistent": js["final"]["consistent"], "json": js,
            "truth": {k: np.asarray(v).tolist() for k, v in p.items()}}
