"""Reflection states in the bootstrap particle filter (issue 6, Bernard ch. 8 and §10.7–10.8).

Two modes, each printing ONE JSON line (with ``os.cpu_count()``); the step cost of the BPF with
Model 3 versus attitude only is ``benchmarks/reflection.py``.

* ``--acceptance`` — §10.7 parameter-only runs: attitude known (the file's truth), Model 3
  with the BPF on the same case with the §10.1 truth perturbation (scenario ``[reflection]``,
  10 % σ, seeded per run), ``--seeds`` runs (default 10). Two variants on the same data: the
  bootstrap filter with Liu–West roughening of z (``plain``) and with one Metropolis
  resample-move step per resampling (``move``). Per parameter: shrink factor = prior σ / final
  posterior σ in physical units (prior σ of p(z) under the filter's Gaussian prior in z, by
  Monte Carlo) and the rate of runs whose final error is inside 3σ. Acceptance (issue 6,
  thesis fig. 10.11f): the −Z facet's ξ and a (``xi[5]``, ``a[5]``) shrink ≥ 2× and end inside
  3σ.
* ``--combined`` — §10.8: attitude and Model 3 estimated together with the BPF at σθ = 3° and
  10° (``--seeds`` runs each, default 5): final attitude error, inside-3σ of the attitude, the
  parameters' inside-3σ rate and shrink; the attitude-only BPF on the same (perturbed) data as
  the reference.

Usage: python benchmarks/reflection_bpf.py --acceptance [--seeds 10] [--particles 10000]
       python benchmarks/reflection_bpf.py --combined [--seeds 5] [--particles 10000]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import warnings

import numpy as np

# run from a source checkout without installing (the package root is the parent folder)
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

SCENARIO = "leo-ic1-fast-spin-controlled-1site.toml"
REFLECTION = "\n[reflection]\nperturb = true\nsigma_frac = 0.1\n"


def scenario_with_reflection():
    """The thesis LEO fast-spin scenario with the §10.1 ``[reflection]`` perturbation."""
    from lightcurve._paths import data_dir
    from lightcurve.io.atomic import atomic_write_text
    from lightcurve.studies.scenario import load_scenario

    src = data_dir("pipelines") / "thesis" / SCENARIO
    with tempfile.TemporaryDirectory(prefix="lc_refl_bpf_") as d:
        path = os.path.join(d, "scenario.toml")
        atomic_write_text(path, src.read_text() + REFLECTION)
        return load_scenario(path)          # loaded eagerly (text, shape, sites)


def truth_vector(lc, names):
    vals = json.loads(lc.attrs["reflection_truth"])
    return np.array([vals[n.split("[")[0]][int(n.split("[")[1][:-1])] for n in names])


def prior_sd_p(fs, n=200_000):
    """σ of p(z) under the filters' Gaussian prior z ~ N(z0, P0) (seeded Monte Carlo)."""
    rng = np.random.default_rng(0x5D)
    z = fs.z0 + rng.standard_normal((n, fs.dim)) * np.sqrt(np.diag(fs.P0))
    return fs.to_p(z).std(axis=0)


# --------------------------------------------------------------------------------------------
# §10.7 and §10.8
# --------------------------------------------------------------------------------------------

def _param_rows(names, shrink, inside):
    shrink, inside = np.asarray(shrink), np.asarray(inside)
    return {n: {"shrink_median": float(np.median(shrink[:, d])),
                "shrink_min": float(np.min(shrink[:, d])),
                "inside_3sigma_rate": float(np.mean(inside[:, d]))}
            for d, n in enumerate(names)}


def acceptance(seeds, particles, moves=1):
    from lightcurve.filters import build_problem, run_bpf
    from lightcurve.filters.facet_states import FacetParameterStates
    from lightcurve.studies.simulate import simulate

    sc = scenario_with_reflection()
    res = {}
    for variant, mv in (("plain", 0), ("move", moves)):
        shrink, inside, runs = [], [], []
        for i in range(seeds):
            lc = simulate(sc, 1000 + i)
            p = build_problem(lc, seed=i)
            fs = FacetParameterStates(p.model.shape)
            psd0 = prior_sd_p(fs)
            tv = truth_vector(lc, fs.names)
            t0 = time.perf_counter()
            e = run_bpf(p, particles=particles, seed=i, facets=fs, attitude="truth",
                        mcmc_moves=mv)
            pm, ps = e.refl_p[-1], e.refl_p_sigma[-1]
            shrink.append(psd0 / ps)
            inside.append(np.abs(tv - pm) <= 3 * ps)
            runs.append({"seed": i, "runtime_s": time.perf_counter() - t0,
                         "xi5": [float(tv[5]), float(pm[5]), float(ps[5])],
                         "a5": [float(tv[11]), float(pm[11]), float(ps[11])],
                         "mcmc_acceptance": e.meta["reflection"].get("mcmc_acceptance")})
        rows = _param_rows(fs.names, shrink, inside)
        S, I = np.asarray(shrink), np.asarray(inside)
        ok = (S[:, 5] >= 2) & (S[:, 11] >= 2) & I[:, 5] & I[:, 11]
        res[variant] = {
            "parameters": rows,
            "observable_shrink_ge2_in_all_runs": [n for n, r in rows.items()
                                                  if r["shrink_min"] >= 2.0],
            "not_observable_median_shrink_lt2": [n for n, r in rows.items()
                                                 if r["shrink_median"] < 2.0],
            "inside_3sigma_rate_all_params": float(np.mean(I)),
            "minus_z_xi_a_pass_runs": int(ok.sum()), "runs": runs}
    return {"mode": "acceptance_10_7", "particles": particles, "seeds": seeds,
            "criterion": "xi[5] and a[5] (-Z facet): shrink >= 2 and |error| <= 3 sigma",
            **res}


def combined(seeds, particles, sigmas=(3.0, 10.0)):
    from lightcurve.filters import build_problem, run_bpf
    from lightcurve.filters.facet_states import FacetParameterStates
    from lightcurve.studies.simulate import simulate

    sc = scenario_with_reflection()
    out = {}
    for st in sigmas:
        runs, shrink, inside = [], [], []
        for i in range(seeds):
            lc = simulate(sc, 2000 + i)
            p = build_problem(lc, seed=i, sigma_theta_deg=st)
            fs = FacetParameterStates(p.model.shape)
            psd0 = prior_sd_p(fs)
            tv = truth_vector(lc, fs.names)
            e = run_bpf(p, particles=particles, seed=i, facets=fs)
            ref = run_bpf(build_problem(lc, seed=i, sigma_theta_deg=st), particles=particles,
                          seed=i)
            s, sr = e.summary(), ref.summary()
            pm, ps = e.refl_p[-1], e.refl_p_sigma[-1]
            shrink.append(psd0 / ps)
            inside.append(np.abs(tv - pm) <= 3 * ps)
            runs.append({"seed": i, "final_att_error_rss_deg": s["final_att_error_rss_deg"],
                         "att_inside_3sigma": s["inside_3sigma"], "diverged": s["diverged"],
                         "params_inside_3sigma": float(np.mean(inside[-1])),
                         "attitude_only_final_att_error_rss_deg": sr["final_att_error_rss_deg"],
                         "attitude_only_diverged": sr["diverged"]})
        errs = [r["final_att_error_rss_deg"] for r in runs]
        out[f"sigma_theta_{st:g}_deg"] = {
            "final_att_error_rss_deg_median": float(np.median(errs)),
            "final_att_error_rss_deg_max": float(np.max(errs)),
            "att_inside_3sigma_runs": int(sum(r["att_inside_3sigma"] for r in runs)),
            "params_inside_3sigma_rate": float(np.mean(inside)),
            "parameters": _param_rows(fs.names, shrink, inside), "runs": runs}
    return {"mode": "combined_10_8", "particles": particles, "seeds": seeds, **out}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, nargs="+", default=None)
    ap.add_argument("--acceptance", action="store_true")
    ap.add_argument("--combined", action="store_true")
    ap.add_argument("--seeds", type=int, default=None)
    ap.add_argument("--moves", type=int, default=1)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    if args.acceptance:
        out = acceptance(args.seeds or 10, (args.particles or [10_000])[0], args.moves)
    elif args.combined:
        out = combined(args.seeds or 5, (args.particles or [10_000])[0])
    else:
        ap.error("choose --acceptance or --combined (the step cost is benchmarks/reflection.py)")
    import numba

    out.update({"wall_s": time.perf_counter() - t0, "cpu_count": os.cpu_count(),
                "numba_threads": numba.get_num_threads(),
                "load_avg_1min": os.getloadavg()[0]})
    print(json.dumps(out))


if __name__ == "__main__":
    main()
