"""emcee reflection-parameter posterior: acceptance and calibration benchmark.

Runs the emcee acceptance: 10 synthetic LEO lightcurves of the cube_1u shape with a
known attitude (fast spin ≈ [2, 1, 3.6] deg/s, 300 epochs over 300 s, 1 % noise, Bernard eq.
9.3), reflection parameters ξ, a, m and areas A of all six facets perturbed per Bernard §10.1
(N(0, (0.1 p)²), seeded), 24 parameters fitted with ``fit_reflection`` (prior = the shape
file's values with 10 % width). A case passes when its chain converged and the truth of every
parameter the diagnostics call identified lies inside the central 99 % posterior interval;
the acceptance is ≥ 9 of 10 cases.

Calibration evidence independent of the 10 cases: simulation-based calibration (SBC, Talts et
al. 2018) with ``reflection_sbc`` — truths drawn from the same prior, 200 synthetic cases per
configuration, 150 epochs: (a) ξ, a, m, A of the glinting +Y facet (4 parameters), (b) the
same for the +Y and +Z facets (8 parameters). The posterior CDF at the truth must be uniform
(chi-square of its histogram and the dispersion statistic Σ Φ⁻¹(u)², family-wise false-alarm
1 % each). For the 10 cases the JSON also gives, per miss, the posterior CDF at the truth and
its z-score, and the probability that a calibrated method fails at least as many cases
(Poisson-binomial over the cases, case i failing with probability 1 − 0.99^k_i for k_i
identified parameters, treated as independent).

The BPF step-cost comparison (Model 3, 24 extra states, versus attitude only) is
``benchmarks/reflection.py``.

Usage: python benchmarks/reflection_emcee.py [--cases 10] [--epochs 300] [--sbc-runs 200]
       [--skip-cases] [--skip-sbc] [--sbc-config 4,8] [--workers 1]
Prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np


def _run_case(seed, epochs, max_steps):
    """One acceptance case (seed 1000 + seed): fit, coverage of the identified parameters."""
    from lightcurve.photometry import load_shape
    from lightcurve.studies.fit_reflection import (
        ConvergenceError,
        ReflectionPosteriorModel,
        fit_reflection,
        synthetic_reflection_case,
    )

    shape = load_shape("cube_1u")
    t0 = time.perf_counter()
    curve, _, vals = synthetic_reflection_case(shape, seed=1000 + seed, n_epochs=epochs)
    model = ReflectionPosteriorModel(shape, curve, curve.truth_q)
    truth = np.array([vals[n.split("[")[0]][int(n.split("[")[1][:-1])] for n in model.names])
    row = {"seed": 1000 + seed}
    try:
        fit = fit_reflection(curve, shape=shape, seed=seed, truth=truth, max_steps=max_steps)
    except ConvergenceError as exc:
        row.update(converged=False, reasons=exc.diagnostics.reasons, passed=False)
    else:
        inside = fit.truth_inside(0.99)
        d = fit.diagnostics
        zt = model.to_z(truth)
        u = np.mean(fit.samples_z < zt[None, :], axis=0)
        zsc = (zt - fit.samples_z.mean(0)) / fit.samples_z.std(0)
        misses = {n: {"u": round(float(u[i]), 4), "z": round(float(zsc[i]), 2),
                      "width_ratio": round(float(fit.width_ratio[i]), 3)}
                  for i, n in enumerate(fit.names) if fit.identified[i] and not inside[i]}
        row.update(converged=True, steps=d.n_steps, tau_max=float(np.max(d.tau)),
                   acceptance=round(d.mean_acceptance, 3),
                   identified=[n for n, i in zip(fit.names, fit.identified) if i],
                   identified_outside_99=[n for n, i, o in zip(fit.names, fit.identified, inside)
                                          if i and not o],
                   misses=misses,
                   all_outside_99=int(np.sum(~inside)),
                   predictive_coverage_95=round(fit.summary()["predictive_coverage_95"], 3),
                   passed=bool(np.all(inside[fit.identified])))
    row["runtime_s"] = round(time.perf_counter() - t0, 1)
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=10)
    ap.add_argument("--epochs", type=int, default=300)
    ap.add_argument("--max-steps", type=int, default=40_000)
    ap.add_argument("--sbc-runs", type=int, default=200)
    ap.add_argument("--sbc-config", default="4,8", help="SBC problem sizes to run (4 and/or 8)")
    ap.add_argument("--skip-cases", action="store_true")
    ap.add_argument("--skip-sbc", action="store_true")
    ap.add_argument("--workers", type=int, default=1, help="processes for the 10 cases")
    args = ap.parse_args()

    from lightcurve.photometry import load_shape
    from lightcurve.studies.fit_reflection import reflection_sbc

    shape = load_shape("cube_1u")
    t_all = time.perf_counter()
    seeds = list(range(0 if args.skip_cases else args.cases))
    if args.workers > 1 and len(seeds) > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        # forkserver: numba's threading layer does not survive fork (see studies/runner.py)
        with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("forkserver")) as ex:
            cases = list(ex.map(_run_case, seeds, [args.epochs] * len(seeds),
                                [args.max_steps] * len(seeds)))
    else:
        cases = [_run_case(seed, args.epochs, args.max_steps) for seed in seeds]
    n_pass = sum(c["passed"] for c in cases)
    # probability of at least this many failing cases if the posterior were calibrated
    p_fail = [1.0 - 0.99 ** len(c.get("identified", [])) for c in cases if c.get("converged")]
    dist = np.array([1.0])
    for pf in p_fail:
        dist = np.convolve(dist, [1.0 - pf, pf])
    n_fail = sum(1 for c in cases if c.get("converged") and not c["passed"])
    p_at_least = float(dist[n_fail:].sum()) if cases else None
    sbc = {}
    configs = {"4": dict(facets=[2], kinds=("xi", "a", "m", "A")),
               "8": dict(facets=[2, 4], kinds=("xi", "a", "m", "A"))}
    for key in ([] if args.skip_sbc else [k.strip() for k in args.sbc_config.split(",")]):
        t0 = time.perf_counter()
        res = reflection_sbc(shape, n_runs=args.sbc_runs, seed0=20_000, n_epochs=150, n_bins=10,
                             false_alarm=0.01, **configs[key])
        res.pop("identified")
        res["u"] = [[round(x, 4) for x in row] for row in res["u"]]
        res["runtime_s"] = round(time.perf_counter() - t0, 1)
        sbc[f"{key}_params"] = res
    print(json.dumps({
        "benchmark": "reflection_emcee", "cpu_count": os.cpu_count(), "shape": "cube_1u",
        "n_params": 24, "epochs": args.epochs, "cases": cases, "n_passed": n_pass,
        "n_cases": len(cases), "acceptance_met": n_pass >= int(np.ceil(0.9 * len(cases))),
        "n_failed_converged": n_fail, "p_at_least_this_many_failures_if_calibrated": p_at_least,
        "sbc": sbc,
        "runtime_s": round(time.perf_counter() - t_all, 1)}))


if __name__ == "__main__":
    main()
