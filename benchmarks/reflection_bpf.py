"""Reflection states in the bootstrap particle filter (Bernard 2021 ch. 8 and §10.7–10.8).

Two modes, each printing ONE JSON line (with ``os.cpu_count()``); the step cost of the BPF with
Model 3 versus attitude only is ``benchmarks/reflection.py``.

* ``--acceptance`` — §10.7 parameter-only runs: attitude known (the file's truth), Model 3
  with the BPF on the same case with the §10.1 truth perturbation (scenario ``[reflection]``,
  10 % σ, seeded per run), ``--seeds`` runs (default 10). Two variants on the same data: the
  bootstrap filter with Liu–West roughening of z (``plain``) and with one Metropolis
  resample-move step per resampling (``move``). Per parameter: shrink factor = prior σ / final
  posterior σ in physical units (prior σ of p(z) under the filter's Gaussian prior in z, by
  Monte Carlo) and the rate of runs whose final error is inside 3σ. Acceptance (thesis
  fig. 10.11f): the −Z facet's ξ and a (``xi[5]``, ``a[5]``) shrink ≥ 2× and end inside
  3σ.
* ``--combined`` — §10.8: attitude and Model 3 estimated together with the BPF at σθ = 3° and
  10° (``--seeds`` runs each, default 5): final attitude error, inside-3σ of the attitude, the
  parameters' inside-3σ rate and shrink; the attitude-only BPF on the same (perturbed) data as
  the reference.

Usage: python benchmarks/reflection_bpf.py --acceptance [--seeds 10] [--particles 10000]
                                           [--scenario PATH]
       (``--scenario``: another scenario file for the §10.7 runs, e.g. pipelines/thesis/
       leo-ch10-fast-spin-eci-controlled-1site.toml, the §10.1 start; the output gives the per-facet
       fraction of epochs lit and visible, ``facet_exposure_seed1000``)
       python benchmarks/reflection_bpf.py --combined [--seeds 5] [--particles 10000]
                                           [--rejuvenation auto|separate|joint]
                                           [--kernel-bandwidth H] [--sigmas 3 10]
                                           [--no-reference]
       (``--rejuvenation separate``: table 7.9 roughening on the attitude and Liu–West on z,
       to compare with the joint kernel)
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


def scenario_with_reflection(path=None, params=None):
    """The thesis LEO fast-spin scenario (or the scenario file ``path``) with the §10.1
    ``[reflection]`` perturbation appended (the file must not have its own ``[reflection]``);
    ``params``: the perturbed kinds (default all: ξ, a, m, A)."""
    from pathlib import Path

    from lightcurve._paths import data_dir
    from lightcurve.io.atomic import atomic_write_text
    from lightcurve.studies.scenario import load_scenario

    src = Path(path) if path else data_dir("pipelines") / "thesis" / SCENARIO
    with tempfile.TemporaryDirectory(prefix="lc_refl_bpf_") as d:
        path = os.path.join(d, "scenario.toml")
        extra = "" if params is None else "params = [%s]\n" % ", ".join(f'"{k}"' for k in params)
        atomic_write_text(path, src.read_text() + REFLECTION + extra)
        return load_scenario(path)          # loaded eagerly (text, shape, sites)


def print_with_machine(out, t0):
    """Add wall time since ``t0`` (perf_counter), core count, numba threads and the 1-minute
    load average to the dict ``out`` and print it as ONE JSON line."""
    import numba

    out.update({"wall_s": time.perf_counter() - t0, "cpu_count": os.cpu_count(),
                "numba_threads": numba.get_num_threads(),
                "load_avg_1min": os.getloadavg()[0]})
    print(json.dumps(out))


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


def acceptance(seeds, particles, moves=1, scenario=None, params=None):
    """§10.7 runs; ``scenario``: path of the scenario file (default: the thesis LEO fast spin);
    ``params``: the kinds perturbed in the truth AND estimated (default all four; e.g.
    ("xi", "a", "m") = areas known exactly, which lifts the a·A degeneracy)."""
    from lightcurve.filters import build_problem, run_bpf
    from lightcurve.filters.facet_states import FacetParameterStates
    from lightcurve.photometry.facet_exposure import facet_exposure_fractions
    from lightcurve.studies.simulate import simulate

    kinds = tuple(params) if params else ("xi", "a", "m", "A")
    sc = scenario_with_reflection(scenario, params)
    # per-facet fraction of epochs lit (n·s > 0) AND visible (n·o > 0), from the truth of seed 1000
    exposure = facet_exposure_fractions(simulate(sc, 1000), shape=sc.shape)
    res = {}
    for variant, mv in (("plain", 0), ("move", moves)):
        shrink, inside, runs = [], [], []
        for i in range(seeds):
            lc = simulate(sc, 1000 + i)
            p = build_problem(lc, seed=i)
            fs = FacetParameterStates(p.model.shape, kinds=kinds)
            psd0 = prior_sd_p(fs)
            tv = truth_vector(lc, fs.names)
            ixi, ia = fs.names.index("xi[5]"), fs.names.index("a[5]")
            t0 = time.perf_counter()
            e = run_bpf(p, particles=particles, seed=i, facets=fs, attitude="truth",
                        mcmc_moves=mv)
            pm, ps = e.refl_p[-1], e.refl_p_sigma[-1]
            shrink.append(psd0 / ps)
            inside.append(np.abs(tv - pm) <= 3 * ps)
            runs.append({"seed": i, "runtime_s": time.perf_counter() - t0,
                         "xi5": [float(tv[ixi]), float(pm[ixi]), float(ps[ixi])],
                         "a5": [float(tv[ia]), float(pm[ia]), float(ps[ia])],
                         "mcmc_acceptance": e.meta["reflection"].get("mcmc_acceptance")})
        rows = _param_rows(fs.names, shrink, inside)
        S, I = np.asarray(shrink), np.asarray(inside)
        ok = (S[:, ixi] >= 2) & (S[:, ia] >= 2) & I[:, ixi] & I[:, ia]
        res[variant] = {
            "parameters": rows,
            "observable_shrink_ge2_in_all_runs": [n for n, r in rows.items()
                                                  if r["shrink_min"] >= 2.0],
            "not_observable_median_shrink_lt2": [n for n, r in rows.items()
                                                 if r["shrink_median"] < 2.0],
            "inside_3sigma_rate_all_params": float(np.mean(I)),
            "minus_z_xi_a_pass_runs": int(ok.sum()), "runs": runs}
    return {"mode": "acceptance_10_7", "particles": particles, "seeds": seeds,
            "scenario": sc.name, "omega_frame": sc.attitude.omega_frame, "params": list(kinds),
            "facet_exposure_seed1000": exposure,
            "criterion": "xi[5] and a[5] (-Z facet): shrink >= 2 and |error| <= 3 sigma",
            **res}


def combined(seeds, particles, sigmas=(3.0, 10.0), rejuvenation="auto", kernel_bandwidth=None,
             reference=True, joint_max_spread_deg=None):
    """§10.8 combined runs (module docstring). ``rejuvenation`` / ``kernel_bandwidth`` go to
    :func:`run_bpf` ("auto" = the joint Liu–West kernel with the Musso bandwidth for Model 3;
    "separate" = separate rejuvenation: table 7.9 on the attitude, Liu–West δ = 0.98 on z).
    Per run also the final NEES of the attitude (3 dof) and of attitude + rate (6 dof), and
    per σθ their sums with the χ² 99.9 % bounds (a consistent filter exceeds them with
    probability 0.1 %). ``reference``: also run the attitude-only BPF on the same data."""
    from scipy.stats import chi2

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
            t0 = time.perf_counter()
            kw = {} if joint_max_spread_deg is None else {
                "joint_max_spread_deg": joint_max_spread_deg}
            e = run_bpf(p, particles=particles, seed=i, facets=fs, rejuvenation=rejuvenation,
                        kernel_bandwidth=kernel_bandwidth, **kw)
            rt = time.perf_counter() - t0
            s = e.summary()
            pm, ps = e.refl_p[-1], e.refl_p_sigma[-1]
            shrink.append(psd0 / ps)
            inside.append(np.abs(tv - pm) <= 3 * ps)
            nees_att = float(np.sum((e.att_error_deg[-1] / e.att_sigma_deg[-1]) ** 2))
            nees_w = float(np.sum((e.omega_error_rad_s[-1] / e.omega_sigma_rad_s[-1]) ** 2))
            row = {"seed": 2000 + i, "final_att_error_rss_deg": s["final_att_error_rss_deg"],
                   "att_inside_3sigma": s["inside_3sigma"], "diverged": s["diverged"],
                   "final_3sigma_att_deg": s["final_3sigma_att_deg"],
                   "nees_att": nees_att, "nees_att_rate": nees_att + nees_w,
                   "params_inside_3sigma": float(np.mean(inside[-1])),
                   "param_z_shrink_median": float(np.median(fs.prior_sd_z
                                                            / e.refl_z_sigma[-1])),
                   "runtime_s": rt}
            if reference:
                sr = run_bpf(build_problem(lc, seed=i, sigma_theta_deg=st),
                             particles=particles, seed=i).summary()
                row.update({"attitude_only_final_att_error_rss_deg":
                            sr["final_att_error_rss_deg"],
                            "attitude_only_diverged": sr["diverged"]})
            runs.append(row)
        errs = [r["final_att_error_rss_deg"] for r in runs]
        n = len(runs)
        out[f"sigma_theta_{st:g}_deg"] = {
            "final_att_error_rss_deg_median": float(np.median(errs)),
            "final_att_error_rss_deg_max": float(np.max(errs)),
            "att_inside_3sigma_runs": int(sum(r["att_inside_3sigma"] for r in runs)),
            "diverged_runs": int(sum(r["diverged"] for r in runs)),
            "nees_att_sum": float(sum(r["nees_att"] for r in runs)),
            "nees_att_sum_chi2_999": float(chi2.ppf(0.999, 3 * n)),
            "nees_att_rate_sum": float(sum(r["nees_att_rate"] for r in runs)),
            "nees_att_rate_sum_chi2_999": float(chi2.ppf(0.999, 6 * n)),
            "params_inside_3sigma_rate": float(np.mean(inside)),
            "parameters": _param_rows(fs.names, shrink, inside), "runs": runs}
    return {"mode": "combined_10_8", "particles": particles, "seeds": seeds,
            "rejuvenation": rejuvenation, "kernel_bandwidth": kernel_bandwidth, **out}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, nargs="+", default=None)
    ap.add_argument("--acceptance", action="store_true")
    ap.add_argument("--combined", action="store_true")
    ap.add_argument("--seeds", type=int, default=None)
    ap.add_argument("--moves", type=int, default=1)
    ap.add_argument("--rejuvenation", default="auto", choices=("auto", "separate", "joint"),
                    help="--combined: the BPF's rejuvenation after resampling (run_bpf)")
    ap.add_argument("--kernel-bandwidth", type=float, default=None,
                    help="--combined: joint-kernel bandwidth h (default: Musso et al. optimum)")
    ap.add_argument("--no-reference", action="store_true",
                    help="--combined: skip the attitude-only reference runs")
    ap.add_argument("--sigmas", type=float, nargs="+", default=[3.0, 10.0],
                    help="--combined: initial attitude σθ values, deg")
    ap.add_argument("--joint-max-spread-deg", type=float, default=None,
                    help="--combined: run_bpf's joint_max_spread_deg (default: run_bpf's)")
    ap.add_argument("--params", default=None,
                    help="--acceptance: comma-separated kinds perturbed and estimated (default "
                    "xi,a,m,A; xi,a,m = areas known)")
    ap.add_argument("--scenario", default=None,
                    help="--acceptance: scenario TOML (default: pipelines/thesis/" + SCENARIO + ")")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    if args.acceptance:
        out = acceptance(args.seeds or 10, (args.particles or [10_000])[0], args.moves,
                         scenario=args.scenario,
                         params=args.params.split(",") if args.params else None)
    elif args.combined:
        out = combined(args.seeds or 5, (args.particles or [10_000])[0], tuple(args.sigmas),
                       args.rejuvenation, args.kernel_bandwidth, not args.no_reference,
                       args.joint_max_spread_deg)
    else:
        ap.error("choose --acceptance or --combined (the step cost is benchmarks/reflection.py)")
    print_with_machine(out, t0)


if __name__ == "__main__":
    main()
