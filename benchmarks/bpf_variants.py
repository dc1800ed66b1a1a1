"""Benchmark: thesis-variant vs robust-variant bootstrap particle filter from a wide prior.

Case: the thesis LEO fast-spin scenario (pipelines/thesis/leo-ic1-fast-spin-controlled-1site.toml,
§9.3.3 IC1, one site, r = 1 %), initial attitude error σθ = 60° per axis, σω = 0.02°/s, the
thesis's 10,000 particles (§9.1), seeds 0…19 (simulation seed = filter seed = the run index).
Each seed runs ``BPFConfig.thesis()`` (the plain bootstrap filter of ch. 7: multinomial
resampling, table 7.9 roughening, no progressive correction, no gate) and ``BPFConfig.robust()``
(progressive correction, joint Liu–West kernel, outlier gate) on the same lightcurve and the
same initial estimate.

Prints ONE JSON line: per variant the final RSS attitude errors (deg) of every seed, their median,
how many end below 5°, how many end with every attitude component inside its own 3σ (the
filter's consistency), how many are flagged diverged, the mean run time; plus the shared footer
(wall time, cores, numba threads, load average) and the scenario's shape and materials (the
shape file in use when this ran).

Usage: python benchmarks/bpf_variants.py [--seeds 20] [--particles 10000] [--sigma-theta 60]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)

SCENARIO = "thesis/leo-ic1-fast-spin-controlled-1site.toml"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--particles", type=int, default=10_000)
    ap.add_argument("--sigma-theta", type=float, default=60.0, help="deg per axis")
    ap.add_argument("--sigma-omega", type=float, default=0.02, help="deg/s per axis")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    import numpy as np

    from lightcurve._paths import data_dir
    from lightcurve.filters import build_problem, run_bpf
    from lightcurve.filters.bpf import BPFConfig
    from lightcurve.studies.scenario import load_scenario
    from lightcurve.studies.simulate import simulate

    sc = load_scenario(data_dir("pipelines") / SCENARIO)
    out = {"benchmark": "bpf_variants", "scenario": SCENARIO, "particles": args.particles,
           "sigma_theta_deg": args.sigma_theta, "sigma_omega_deg_s": args.sigma_omega,
           "seeds": args.seeds, "variants": {}}
    res = {v: {"final_att_error_rss_deg": [], "inside_3sigma": [], "diverged": [],
               "runtime_s": []} for v in ("thesis", "robust")}
    for seed in range(args.seeds):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lc = simulate(sc, seed)
        p = build_problem(lc, seed=seed, sigma_theta_deg=args.sigma_theta,
                          sigma_omega_deg_s=args.sigma_omega)
        if seed == 0:
            sh = p.model.shape
            out["shape"] = getattr(sh, "name", "")
            out["materials"] = [str(getattr(f, "material", "")) for f in getattr(sh, "facets", [])]
        for v in res:
            cfg = BPFConfig(variant=v, particles=args.particles)
            est = run_bpf(p, cfg, seed=seed)
            s = est.summary()
            err = est.att_error_deg[-1]
            sig = est.att_sigma_deg[-1]
            r = res[v]
            r["final_att_error_rss_deg"].append(float(s["final_att_error_rss_deg"]))
            r["inside_3sigma"].append(bool(np.all(np.abs(err) <= 3.0 * sig)))
            r["diverged"].append(bool(est.diverged))
            r["runtime_s"].append(float(est.runtime_s))
    for v, r in res.items():
        e = np.array(r["final_att_error_rss_deg"])
        out["variants"][v] = {
            "final_att_error_rss_deg": [round(x, 3) for x in e.tolist()],
            "median_final_error_deg": float(np.median(e)),
            "below_5deg": int(np.sum(e < 5.0)),
            "inside_3sigma": int(np.sum(r["inside_3sigma"])),
            "diverged_flagged": int(np.sum(r["diverged"])),
            "mean_runtime_s": float(np.mean(r["runtime_s"]))}
    print_with_machine(out, t0)


if __name__ == "__main__":
    main()
