"""Concealed-effect confusion matrix of ``lightcurve diagnose`` against an independent simulator.

For every effect of the physics registry (magnitude and coarse-sun-sensor) and for "none"
(lightcurve and CSS): ``--seeds`` recordings made by the plain-NumPy generator of
``tests/diagnosis/concealed.py`` (no import of the package's photometry or physics; Table 9.2
cube) with the effect at random realistic parameters, diagnosed against the package's model
without it (``tests/diagnosis/concealed_cases.py``: which scenario shows which effect, and
why). Acceptance per effect: named first AND held-out χ²/n < 1.5 in ≥ 9/10 seeds;
"none" consistent in ≥ 9/10; no effect named with an unidentified parameter.

Prints ONE JSON line: per case the confusion row (how often each effect was named first,
"(consistent)" for a consistent verdict, "(nothing named)" for a mismatch without a named
effect), the counts named_first, held_out_below_1_5, both, consistent, named_unidentified,
the held-out χ²/n per seed, the wall time per case; plus the shared footer (wall time, cores,
numba threads, load).

Usage: python benchmarks/diagnosis_confusion.py [--seeds 10] [--cases a,b,...] [--workers N]
       [--verbose]   (--verbose: one JSON line per recording on stderr as it finishes)

On a shared machine: NUMBA_NUM_THREADS=1 (results are identical; every output element of the
parallel kernels is independent).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests" / "diagnosis"))

from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)

from lightcurve.studies.runner import limit_blas_threads  # noqa: E402

limit_blas_threads()   # small dense fits: threaded BLAS only spins (children inherit the env)


def _one(args):
    case, seed = args
    import warnings

    import concealed_cases as C

    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    try:
        r = C.run_case(case, seed)
    except Exception as exc:  # a crash is a failed seed, reported
        return {"case": case, "seed": seed, "error": f"{type(exc).__name__}: {exc}",
                "wall_s": time.perf_counter() - t0}
    r.pop("json")
    r["wall_s"] = time.perf_counter() - t0
    return r


def main():
    import concealed_cases as C

    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--cases", default=",".join(C.CASES), help="comma-separated: " + ", ".join(C.CASES))
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--verbose", action="store_true")
    a = ap.parse_args()
    cases = [c.strip() for c in a.cases.split(",") if c.strip()]
    for c in cases:
        if c not in C.CASES:
            ap.error(f"unknown case {c!r}; known: {', '.join(C.CASES)}")
    t0 = time.perf_counter()
    # seed-major order: an interrupted run has the first seeds of every case
    jobs = [(c, s) for s in range(a.seeds) for c in cases]
    results = []

    def done(r):
        results.append(r)
        if a.verbose:
            print(json.dumps({k: r.get(k) for k in ("case", "seed", "verdict", "chosen", "first",
                                                     "held_out_chi2_per_n", "unidentified",
                                                     "named_unidentified", "error", "wall_s")}),
                  file=sys.stderr, flush=True)

    if a.workers > 1:
        with ProcessPoolExecutor(a.workers) as ex:
            for r in ex.map(_one, jobs):
                done(r)
    else:
        for j in jobs:
            done(_one(j))
    out = {"benchmark": "diagnosis_confusion", "seeds": a.seeds, "cases": {}}
    for c in cases:
        rs = [r for r in results if r["case"] == c]
        truth = c.split("@", 1)[0]
        conf, first, below, both, cons, unid, held, errors = {}, 0, 0, 0, 0, 0, [], []
        for r in rs:
            if "error" in r:
                errors.append(r["error"])
                conf["(error)"] = conf.get("(error)", 0) + 1
                continue
            key = "(consistent)" if r["verdict"] == "consistent" else (r["first"] or "(nothing named)")
            conf[key] = conf.get(key, 0) + 1
            ok_first = r["first"] == truth
            h = r["held_out_chi2_per_n"]
            ok_held = h is not None and h < 1.5
            first += ok_first
            below += ok_held
            both += ok_first and ok_held
            cons += r["verdict"] == "consistent"
            unid += bool(r["named_unidentified"])
            held.append(None if h is None else round(h, 3))
        out["cases"][c] = {"confusion": conf, "named_first": first, "held_out_below_1_5": below,
                           "named_first_and_held_out_below_1_5": both, "consistent": cons,
                           "named_unidentified": unid, "held_out_chi2_per_n": held,
                           "errors": errors,
                           "wall_s": round(sum(r["wall_s"] for r in rs), 1)}
    print_with_machine(out, t0)


if __name__ == "__main__":
    main()
