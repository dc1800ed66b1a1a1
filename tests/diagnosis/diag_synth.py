"""Concealed-effect cases for the diagnosis proofs (tests and benchmarks/diagnosis_confusion.py).

Each case simulates one of the scenarios in ``pipelines/diagnosis/`` with one effect switched
on at random realistic parameters (the effect's own ``sample_params``, fixed seed), then
diagnoses the lightcurve with the same scenario *without* the effect (attitude = the file's
truth, nothing free). Scenario choice per effect (where the effect is physically observable):

* ``diag-leo-lit-2site``: lit two-site LEO pass, elevations 5–73°: extinction, zero_point,
  unmodelled_facet, specular_glint, and the no-effect case. Earthshine is run here too but
  is NOT observable in this geometry: seen from a dark site, the LEO object sees almost no
  sunlit Earth (≤ 2 sunlit 10° cells in view, Δm < 1e-5 mag), so the data equal the
  no-effect data; a dedicated Earthshine geometry is still to be found;
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
}
CASE_SCENARIO = {"none": "lit", "extinction": "lit", "zero_point": "lit", "earthshine": "lit",
                 "unmodelled_facet": "lit", "specular_glint": "lit", "penumbra": "shadow",
                 "light_time": "geo", "clock_offset": "geo", "exposure_smearing": "geo"}

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

    sc = scenario(CASE_SCENARIO[effect])
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
    d = diagnose(prob, cross_validation=False, **diag_kw)
    js = d.summary()
    ranked = [c["name"] for c in js["candidates"] if c.get("applicable")]
    return {"effect": effect, "seed": seed, "n": js["n"], "verdict": js["verdict"],
            "top": ranked[0] if ranked else None, "chosen": js["chosen"],
            "baseline_chi2_dof": js["baseline"]["chi2_dof"], "final_chi2_dof": js["final"]["chi2_dof"],
            "final_consistent": js["final"]["consistent"], "json": js}
