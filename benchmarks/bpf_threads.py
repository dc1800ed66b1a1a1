"""Benchmark: the CPU particle filter on 1 and on 2 numba threads for small clouds — the
measurement behind ``lightcurve.filters.bpf.PARTICLES_PER_THREAD`` (the smallest share of the
cloud that is worth a thread of its own).

Scenario: as ``benchmarks/particle_filter.py`` (the bundled thesis LEO fast-spin case, 73
epochs, σθ = 60°, σω = 0.02°/s). For each particle count and mode (plain bootstrap and the
progressive correction) the filter runs ``--repeats`` times on each thread count, alternating,
with the thread rule switched off (every count may use every thread), after a small warm-up
run that compiles / loads the numba cache. The best wall time of each is reported: the rule
should pick the faster one.

Prints ONE JSON line: per (particles, mode) the best and all wall times (s) on 1 and 2
threads, the particle·steps per second of the best, which thread count was faster and the
thread count the rule picks (``bpf_threads``); plus the shared footer (wall time, cores,
numba threads, load average).

Usage: python benchmarks/bpf_threads.py [--particles 5000 10000 20000 40000 70000]
       [--repeats 3] [--modes plain progressive]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--particles", type=int, nargs="+",
                    default=[5000, 10000, 20000, 40000, 70000])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--modes", nargs="+", default=["plain", "progressive"],
                    choices=["plain", "progressive"])
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    warnings.simplefilter("ignore")
    import numba

    from lightcurve._paths import data_dir
    from lightcurve.filters import build_problem
    from lightcurve.filters import bpf as B
    from lightcurve.studies.scenario import load_scenario
    from lightcurve.studies.simulate import simulate
    from lightcurve.threads import limited_threads

    if numba.config.NUMBA_NUM_THREADS < 2:
        raise SystemExit("bpf_threads.py: needs 2 numba threads (NUMBA_NUM_THREADS >= 2)")
    sc = load_scenario(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")
    prob = build_problem(simulate(sc, 1), seed=0, sigma_theta_deg=60.0, sigma_omega_deg_s=0.02)
    rule = B.PARTICLES_PER_THREAD
    B.PARTICLES_PER_THREAD = 1          # the rule off: the thread count below decides
    try:
        rows = []
        for mode in a.modes:
            prog = mode == "progressive"
            B.run_bpf(prob, particles=1000, seed=0, progressive=prog)   # warm-up
            for N in a.particles:
                times = {1: [], 2: []}
                for _ in range(a.repeats):
                    for th in (1, 2):
                        with limited_threads(th):
                            t1 = time.perf_counter()
                            est = B.run_bpf(prob, particles=N, seed=0, progressive=prog)
                            times[th].append(time.perf_counter() - t1)
                best = {th: min(v) for th, v in times.items()}
                rows.append({"particles": N, "mode": mode, "epochs": len(est),
                             "best_s_1": best[1], "best_s_2": best[2],
                             "times_s_1": times[1], "times_s_2": times[2],
                             "steps_per_s_1": N * len(est) / best[1],
                             "steps_per_s_2": N * len(est) / best[2],
                             "faster": 1 if best[1] <= best[2] else 2,
                             "rule_threads": max(1, -(-N // rule))})
    finally:
        B.PARTICLES_PER_THREAD = rule
    print_with_machine({"benchmark": "bpf_threads", "particles_per_thread": rule,
                        "affinity_cores": len(os.sched_getaffinity(0)), "rows": rows}, t0)


if __name__ == "__main__":
    main()
