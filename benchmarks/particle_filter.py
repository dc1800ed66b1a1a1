"""Benchmark: bootstrap particle filter (numba) vs the same algorithm in plain NumPy.

Scenario: the bundled thesis LEO fast-spin case (pipelines/thesis/leo-ic1-fast-spin-controlled-1site.toml: controlled 1U cube,
Socorro, 73 epochs, r = 1 %), σθ = 60°, σω = 0.02°/s; each size is run with the progressive
correction (the default filter, which re-predicts the cloud at every tempering stage:
``predictions_per_particle`` counts those) and as the plain bootstrap filter of the thesis. Each configuration runs in a fresh
subprocess (after a small warm-up run that compiles / loads the numba cache) so its peak
resident memory (ru_maxrss, whole process incl. the interpreter and numba) is its own; the
peak of traced Python/NumPy allocations (tracemalloc) is reported too.

Prints ONE JSON line: per configuration particle·steps per second (particles × epochs /
filter run time), run time, peak RSS (MB), traced peak (MB), final RSS attitude error, and
the numba/NumPy speed-up; plus os.cpu_count() and numba's thread count.

Usage: python benchmarks/particle_filter.py [--particles 10000 100000] [--numpy-max 100000]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

CHILD = r"""
import json, resource, sys, time, tracemalloc, warnings
warnings.simplefilter("ignore")
import numpy as np
from lightcurve._paths import data_dir
from lightcurve.studies.scenario import load_scenario
from lightcurve.studies.simulate import simulate
from lightcurve.filters import build_problem, run_bpf, run_bpf_numpy

backend, N, prog = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
sc = load_scenario(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")
lc = simulate(sc, 1)
prob = build_problem(lc, seed=0, sigma_theta_deg=60.0, sigma_omega_deg_s=0.02)
run = run_bpf if backend == "numba" else run_bpf_numpy
run(prob, particles=1000, seed=0, progressive=prog)   # warm-up: compile / load numba cache
tracemalloc.start()
t0 = time.perf_counter()
est = run(prob, particles=N, seed=0, progressive=prog)
dt = time.perf_counter() - t0
_, traced = tracemalloc.get_traced_memory()
tracemalloc.stop()
rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(json.dumps({"backend": backend, "particles": N, "progressive": prog, "epochs": len(est),
                  "runtime_s": dt, "particle_steps_per_s": N * len(est) / dt,
                  "peak_rss_mb": rss_mb, "traced_peak_mb": traced / 2**20,
                  "final_att_error_rss_deg": est.summary()["final_att_error_rss_deg"],
                  "tempering_stages": int(np.sum(est.meta["tempering_stages"])),
                  "predictions_per_particle": len(est) + int(np.sum(est.meta["tempering_stages"]))}))
"""


def _child(backend, n, progressive=True):
    env = dict(os.environ)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    out = subprocess.run([sys.executable, "-c", CHILD, backend, str(n), "1" if progressive else "0"],
                         capture_output=True,
                         text=True, env=env, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, nargs="+", default=[10_000, 100_000])
    ap.add_argument("--numpy-max", type=int, default=100_000,
                    help="largest particle count also run with the NumPy reference")
    args = ap.parse_args(argv)
    import numba

    res = {"benchmark": "particle_filter", "cpu_count": os.cpu_count(),
           "numba_threads": numba.config.NUMBA_NUM_THREADS, "runs": []}
    for n in args.particles:
        for prog in (True, False):
            a = _child("numba", n, prog)
            res["runs"].append(a)
            if n <= args.numpy_max:
                b = _child("numpy", n, prog)
                res["runs"].append(b)
                a["speedup_vs_numpy"] = b["runtime_s"] / a["runtime_s"]
    print(json.dumps(res))


if __name__ == "__main__":
    main()
