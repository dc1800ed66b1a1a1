"""Concealed-effect proof of `lightcurve diagnose` (issue 10): the full confusion matrix.

For every magnitude effect with a proof scenario (tests/diagnosis/diag_synth.py: which
scenario and why) and for "none" (also "none@meo", "none@mesh": no effect in the Earthshine
and self-shadowing scenarios): 10 seeds; simulate with the effect on at random realistic
parameters, diagnose with it off. A case "<effect>@<scenario>" runs an effect in another
scenario (e.g. "earthshine@lit", where it is not observable). Prints ONE JSON line: per true effect the count of seeds
in which each effect ranked first ("confusion"), how often the true effect ranked first,
how often final chi2/dof < 1.5, how often the verdict was "consistent" (for "none"), the
wall time and os.cpu_count().

Usage: python benchmarks/diagnosis_confusion.py [--seeds 10] [--effects a,b,...] [--verbose]

Tip for a shared, oversubscribed machine: NUMBA_NUM_THREADS=1 (the parallel numba kernels
then avoid thread contention; results are identical, every output element is independent).
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "diagnosis"))

from diag_synth import CASE_SCENARIO, DEFAULT_CASES, SCEN, case_effect, run_case  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--effects", default=",".join(DEFAULT_CASES),
                    help="comma-separated cases (default: all): " + ", ".join(DEFAULT_CASES))
    ap.add_argument("--verbose", action="store_true")
    a = ap.parse_args()
    t0 = time.perf_counter()
    out = {"seeds": a.seeds, "cpu_count": os.cpu_count(), "effects": {}}
    cases = [c.strip() for c in a.effects.split(",") if c.strip()]
    for eff in cases:
        if "@" not in eff and eff not in CASE_SCENARIO:
            ap.error(f"unknown case {eff!r}; known: {', '.join(DEFAULT_CASES)}")
        name, key = case_effect(eff)
        conf, first, below, consistent, finals = {}, 0, 0, 0, []
        t_case = time.perf_counter()
        for seed in range(a.seeds):
            r = run_case(eff, seed)
            top = r["top"] if r["verdict"] == "mismatch" else "(consistent)"
            conf[top] = conf.get(top, 0) + 1
            first += int(r["top"] == name and r["verdict"] == "mismatch")
            below += int(r["final_chi2_dof"] < 1.5)
            consistent += int(r["verdict"] == "consistent")
            finals.append(round(r["final_chi2_dof"], 3))
            if a.verbose:
                print(eff, seed, r["verdict"], r["top"], r["chosen"], round(r["baseline_chi2_dof"], 2),
                      round(r["final_chi2_dof"], 3), "truth", r["truth"], "fitted",
                      json.dumps(r["json"].get("chosen_params", {})), file=sys.stderr, flush=True)
        out["effects"][eff] = {"scenario": SCEN[key], "confusion": conf,
                               "ranked_first": first, "final_chi2_dof_below_1_5": below,
                               "verdict_consistent": consistent, "final_chi2_dof": finals,
                               "wall_s": round(time.perf_counter() - t_case, 1)}
    out["wall_s"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
