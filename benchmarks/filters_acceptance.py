"""Filter acceptance runs on the thesis LEO fast-spin case (pipelines/thesis/leo-ic1-fast-spin-controlled-1site.toml).

Controlled 1U cube seen from Socorro, σω = 0.02°/s, r = 1 %, eclipse ignored as in the thesis
(Bernard 2021 §9.3.3). Each run i simulates the lightcurve with seed i (truth ACS noise and
measurement noise) and starts the filter from the truth perturbed with seed i.

* σθ = 3°, ``--runs`` (default 100) runs of the UKF and the MEKF: how many end with all six
  components (3 attitude, 3 rate) inside ±3σ (thesis fig. 9.4);
* NEES of the UKF averaged over the first ``--nees-runs`` (default 50) runs, per epoch, against
  the two-sided 99 % chi-square band ``χ²_{6R}(0.005, 0.995)/R``;
* σθ = 60°, ``--bpf-runs`` (default 10) seeds of the BPF with ``--particles`` (default 10,000):
  how many end with RSS attitude error < 5° (thesis fig. 9.5c–e); the MEKF and UKF from 60°
  for comparison.

Prints ONE JSON line (plus os.cpu_count()).
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--nees-runs", type=int, default=50)
    ap.add_argument("--bpf-runs", type=int, default=10)
    ap.add_argument("--particles", type=int, default=10_000)
    ap.add_argument("--gate", choices=("auto", "reject", "inflate", "off"), default="auto",
                    help="innovation gate of the filters (lightcurve.filters.gating; default auto)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from lightcurve._paths import data_dir
    from lightcurve.estimation.consistency import chi2_interval
    from lightcurve.filters import invert
    from lightcurve.studies.scenario import load_scenario
    from lightcurve.studies.simulate import simulate

    sc = load_scenario(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")
    t0 = time.perf_counter()
    res = {"benchmark": "filters_acceptance", "cpu_count": os.cpu_count(), "gate": args.gate}
    gate_flagged = {"ukf": 0, "mekf": 0, "bpf": 0}
    inside = {"ukf": 0, "mekf": 0}
    diverged = {"ukf": 0, "mekf": 0}
    final_err = {"ukf": [], "mekf": []}
    nees = {"ukf": [], "mekf": []}
    curves = {}
    for i in range(args.runs):
        lc = simulate(sc, i)
        if i < args.bpf_runs:
            curves[i] = lc
        for m in ("ukf", "mekf"):
            e = invert(lc, m, seed=i, sigma_theta_deg=3.0, sigma_omega_deg_s=0.02, gate=args.gate)
            s = e.summary()
            gate_flagged[m] += s.get("rejected_outliers", 0) + s.get("inflated_outliers", 0)
            inside[m] += s["inside_3sigma"]
            diverged[m] += s["diverged"]
            final_err[m].append(s["final_att_error_rss_deg"])
            if i < args.nees_runs:
                nees[m].append(e.nees)
    lo, hi = chi2_interval(6, 0.99, args.nees_runs)
    for m in ("ukf", "mekf"):
        avg = np.mean(np.array(nees[m]), axis=0)
        res[m] = {"runs": args.runs, "inside_3sigma": inside[m], "diverged": diverged[m],
                  "median_final_att_error_deg": float(np.median(final_err[m])),
                  "nees_runs": args.nees_runs, "nees_band_99": [lo, hi],
                  "nees_epochs_inside_band": float(np.mean((avg >= lo) & (avg <= hi))),
                  "nees_epochs_below_band": float(np.mean(avg < lo)),
                  "nees_epochs_above_band": float(np.mean(avg > hi)),
                  "nees_mean_last_half": float(np.mean(avg[len(avg) // 2:]))}
    bpf = []
    for i in range(args.bpf_runs):
        row = {"seed": i}
        for m in ("bpf", "ukf", "mekf"):
            e = invert(curves[i], m, seed=i, sigma_theta_deg=60.0, sigma_omega_deg_s=0.02,
                       particles=args.particles, gate=args.gate)
            s = e.summary()
            if m == "bpf":
                gate_flagged[m] += s.get("rejected_outliers", 0) + s.get("inflated_outliers", 0)
            row[m] = {"final_att_error_rss_deg": s["final_att_error_rss_deg"],
                      "inside_3sigma": s["inside_3sigma"], "diverged": s["diverged"],
                      "runtime_s": s["runtime_s"]}
        bpf.append(row)
    res["sigma60"] = {
        "particles": args.particles, "runs": bpf,
        "bpf_below_5deg": int(sum(r["bpf"]["final_att_error_rss_deg"] < 5 for r in bpf)),
        "ukf_below_5deg": int(sum(r["ukf"]["final_att_error_rss_deg"] < 5 for r in bpf)),
        "mekf_below_5deg": int(sum(r["mekf"]["final_att_error_rss_deg"] < 5 for r in bpf)),
    }
    res["gate_flagged_total"] = gate_flagged
    res["wall_s"] = time.perf_counter() - t0
    print(json.dumps(res))


if __name__ == "__main__":
    main()
