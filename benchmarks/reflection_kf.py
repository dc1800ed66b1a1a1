"""Acceptance runs of the reflection models in the Kalman filters (Bernard 2021 §10.2–10.8).

Prints ONE JSON line. Three parts (all truth shapes perturbed by 10 % per parameter, §10.1,
the filters using the nominal shape):

1. ``geo_model1`` — nadir GEO IC2 of ch. 10 (pipelines/thesis/geo-ch10-ic2-nadir-controlled-1site
   .toml, Bernard §9.3.5 and §10.1) with Model 1 site biases (fig. 10.3): innovation χ²/dof w.r.t. the
   measurement noise alone (ν²/σ²), NIS (ν²/S), and post-fit residuals
   ``y − m(q̂) − b̂`` RMS / σ, attitude known and attitude estimated.
2. ``sec10_7`` — LEO IC1 fast spin, controlled, 1 site (eclipse ignored as in the thesis),
   Model 3 with the attitude known, MEKF and UKF: per parameter the fraction of seeds whose
   physical 1σ shrinks ≥ 2× (prior/final) and whose final error is inside 3σ.
3. ``sec10_8`` — combined attitude + parameter runs: Models 1 and 2 (and no model) on the GEO
   case at σθ = 3°, Model 3 (and no model) on the LEO fast-spin case at σθ = 3° and 10°, MEKF
   and UKF, ``--seeds`` seeds each; and the same LEO case with the parameters known ("known":
   truth parameters not perturbed, so the filter's shape is the truth's — the "perfect
   knowledge of the shape model reflection parameters" of §10.4). Success = final attitude
   error inside 3σ on every axis, RSS below 5°, and not flagged diverged.

Usage: ``python benchmarks/reflection_kf.py [--seeds 10] [--parts geo,107,108] [--scenario PATH]``
(nice -n 10 on a shared machine); ``--scenario`` replaces the LEO file of the ``107`` part, e.g.
pipelines/thesis/leo-ch10-fast-spin-eci-controlled-1site.toml (the §10.1 start, body = ECI: the
−Z facet is lit and seen). The ``107`` output also gives the per-facet fraction of epochs lit
and visible (truth of the first seed).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lightcurve._paths import data_dir  # noqa: E402
from lightcurve.filters.invert import invert  # noqa: E402
from lightcurve.filters.models import MagnitudeModel  # noqa: E402
from lightcurve.studies.scenario import load_scenario  # noqa: E402
from lightcurve.studies.simulate import simulate  # noqa: E402

THESIS = data_dir("pipelines") / "thesis"
GEO = THESIS / "geo-ch10-ic2-nadir-controlled-1site.toml"
# §10.1: ch. 10's LEO fast spin starts with the body frame on ECI (the file carries [reflection])
LEO = THESIS / "leo-ch10-fast-spin-eci-controlled-1site.toml"
#: filter variant and Cook–Torrance form of every run (--variant, --cook-torrance)
OPTS = {"variant": "robust", "cook_torrance": "physical"}
REFL = '\n[reflection]\nperturb = true\nsigma_frac = 0.1\nparams = ["xi", "a", "m", "A"]\n'


def _scenario(path, add_reflection, params=("xi", "a", "m", "A")):
    """Load the scenario ``path``, with the §10.1 ``[reflection]`` perturbation of ``params``
    inserted when ``add_reflection``."""
    from dataclasses import replace

    from lightcurve.studies.scenario import with_cook_torrance_form

    txt = Path(path).read_text()
    plist = ", ".join(f'"{k}"' for k in params)
    refl = REFL.replace('"xi", "a", "m", "A"', plist)
    if "[reflection]" in txt:
        txt = txt.replace('params = ["xi", "a", "m", "A"]', f"params = [{plist}]")
    elif add_reflection:
        # [effects] is the last table of some files: append [reflection] before it
        txt = txt.replace("\n[effects]", refl + "\n[effects]") if "[effects]" in txt \
            else txt + refl
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / Path(path).name
        p.write_text(txt)
        sc = load_scenario(p)
    return replace(sc, shape=with_cook_torrance_form(sc.shape, OPTS["cook_torrance"]))


def _sim(sc, seed):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(sc, seed=seed)


def truth_vector(curve, names):
    """Truth of the Model 3 states (names "kind[facet]") from attrs["reflection_truth"]."""
    tr = json.loads(curve.attrs["reflection_truth"])
    out = []
    for n in names:
        kind, f = n[:-1].split("[")
        out.append(tr[kind][int(f)])
    return np.array(out, float)


def postfit(curve, est):
    """Post-fit residuals y − m(q̂_k) − b̂_site (mag) with the nominal shape."""
    m = MagnitudeModel(curve.resolve_shape(), curve)
    yh = np.array([m.predict_q(est.q[k][None, :], k)[0] for k in range(len(curve))])
    if est.bias is not None:
        yh = yh + est.bias[np.arange(len(curve)), m.site]
    return curve.mag - yh


def success(est, max_deg=5.0):
    s = est.summary()
    return bool(s.get("inside_3sigma", False) and s["final_att_error_rss_deg"] < max_deg
                and not est.diverged)


def part_geo_model1(seeds):
    sc = _scenario(GEO, False)
    rows = {}
    for method in ("mekf", "ukf"):
        for att in ("truth", "estimate"):
            chi, nis, rms_post, bias_err, ok = [], [], [], [], []
            for seed in seeds:
                c = _sim(sc, seed)
                e = invert(c, method, seed=seed, reflection="model1", attitude=att,
                           sigma_theta_deg=3.0, variant=OPTS["variant"])
                sig = c.mag_sigma
                v = np.isfinite(e.innovations)
                chi.append(float(np.mean(e.innovations[v] ** 2 / sig[v] ** 2)))
                nis.append(float(np.mean(e.innovations[v] ** 2 / e.innovation_var[v])))
                r = postfit(c, e)
                rms_post.append(float(np.sqrt(np.mean(r ** 2)) / np.mean(sig)))
                # the "true" bias: mean truth-shape minus nominal-shape magnitude along the truth
                mm = MagnitudeModel(c.resolve_shape(), c)
                mnom = np.array([mm.predict_q(c.truth_q[k][None, :], k)[0] for k in range(len(c))])
                db = float(np.mean(c.truth_mag - mnom))
                bias_err.append((float(e.bias[-1, 0]) - db, float(e.bias_sigma[-1, 0])))
                if att == "estimate":
                    ok.append(success(e))
            rows[f"{method}_{att}"] = {
                "innovation_chi2_dof_vs_R": [round(x, 3) for x in chi],
                "nis_mean": [round(x, 3) for x in nis],
                "postfit_rms_over_sigma": [round(x, 3) for x in rms_post],
                "bias_minus_mean_true_offset_mag": [round(a, 4) for a, _ in bias_err],
                "bias_sigma_mag": [round(b, 4) for _, b in bias_err],
                **({"attitude_success": int(sum(ok)), "runs": len(ok)} if ok else {}),
            }
    return rows


def part_sec10_7(seeds, scenario=None, params=("xi", "a", "m", "A")):
    """§10.7 runs on ``scenario`` (path; default the thesis LEO fast-spin file); ``params``: the
    kinds perturbed in the truth and estimated (("xi", "a", "m"): areas known)."""
    from lightcurve.photometry.facet_exposure import facet_exposure_fractions

    sc = _scenario(scenario or LEO, True, params)
    # per-facet fraction of epochs lit (n·s > 0) AND visible (n·o > 0), truth of the first seed
    out = {"scenario": sc.name, "omega_frame": sc.attitude.omega_frame, "params": list(params),
           "facet_exposure_first_seed": facet_exposure_fractions(_sim(sc, seeds[0]), shape=sc.shape)}
    for method in ("ukf", "mekf"):
        shrink, inside, err_sig = [], [], []
        names = None
        for seed in seeds:
            c = _sim(sc, seed)
            e = invert(c, method, seed=seed, reflection="model3", attitude="truth",
                       reflection_kinds=params, variant=OPTS["variant"])
            names = e.refl_names
            tv = truth_vector(c, names)
            prior = np.array(e.meta["reflection"]["prior_sigma_p"])
            shrink.append(prior / e.refl_p_sigma[-1])
            z = (e.refl_p[-1] - tv) / e.refl_p_sigma[-1]
            err_sig.append(z)
            inside.append(np.abs(z) <= 3.0)
        shrink, inside, err_sig = np.array(shrink), np.array(inside), np.array(err_sig)
        out[method] = {n: {"shrink_median": round(float(np.median(shrink[:, d])), 2),
                           "frac_shrink_ge2": round(float(np.mean(shrink[:, d] >= 2)), 2),
                           "frac_inside_3sigma": round(float(np.mean(inside[:, d])), 2),
                           "rms_err_over_sigma": round(float(np.sqrt(np.mean(err_sig[:, d] ** 2))), 2)}
                       for d, n in enumerate(names)}
        out[method + "_observable"] = [n for d, n in enumerate(names)
                                       if np.mean(shrink[:, d] >= 2) >= 0.5]
    return out


def part_sec10_8(seeds):
    from dataclasses import replace

    out = {}
    geo = _scenario(GEO, False)
    leo = _scenario(LEO, True)
    known = replace(leo, reflection=None)   # truth parameters = the filter's (§10.4)
    cases = [("geo", geo, 3.0, m) for m in ("none", "model1", "model2")]
    cases += [("leo_fast", leo, st, m) for st in (3.0, 10.0) for m in ("none", "model3")]
    cases += [("leo_fast", known, st, "known") for st in (3.0, 10.0)]
    for name, sc, st, model in cases:
        curves = [_sim(sc, s) for s in seeds]
        for method in ("mekf", "ukf"):
            ok, rss, inside, div = [], [], [], []
            for seed, c in zip(seeds, curves):
                e = invert(c, method, seed=seed, reflection="none" if model == "known" else model,
                           sigma_theta_deg=st, variant=OPTS["variant"])
                s = e.summary()
                ok.append(success(e))
                rss.append(round(s["final_att_error_rss_deg"], 3))
                inside.append(bool(s["inside_3sigma"]))
                div.append(bool(e.diverged))
            out[f"{name}_sth{int(st)}_{model}_{method}"] = {
                "success": int(sum(ok)), "runs": len(ok), "inside_3sigma": int(sum(inside)),
                "diverged": int(sum(div)), "final_rss_deg": rss}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--parts", default="geo,107,108")
    ap.add_argument("--scenario", default=None,
                    help="scenario TOML of the 107 part (default: " + LEO.name + ")")
    ap.add_argument("--params", default="xi,a,m,A",
                    help="kinds perturbed and estimated in the 107 part (default xi,a,m,A; "
                    "xi,a,m = areas known)")
    ap.add_argument("--variant", choices=("robust", "thesis"), default="robust",
                    help="filters: robust (default) or thesis (Bernard ch. 7-8 as written)")
    ap.add_argument("--cook-torrance", choices=("physical", "thesis"), default="physical",
                    help="Cook-Torrance diffuse term of truth and filters (thesis = eq. 5.8)")
    a = ap.parse_args(argv)
    OPTS.update(variant=a.variant, cook_torrance=a.cook_torrance)
    seeds = list(range(1, a.seeds + 1))
    parts = a.parts.split(",")
    t0 = time.perf_counter()
    res = {"benchmark": "reflection_kf", "cpu_count": os.cpu_count(), "seeds": seeds,
           "variant": a.variant, "cook_torrance": a.cook_torrance,
           "load_avg_start": os.getloadavg()[0]}
    if "geo" in parts:
        res["geo_model1"] = part_geo_model1(seeds[:3])
    if "107" in parts:
        res["sec10_7"] = part_sec10_7(seeds, a.scenario, tuple(a.params.split(",")))
    if "108" in parts:
        res["sec10_8"] = part_sec10_8(seeds)
    res["wall_s"] = round(time.perf_counter() - t0, 1)
    res["load_avg_end"] = os.getloadavg()[0]
    print(json.dumps(res))


if __name__ == "__main__":
    main()
