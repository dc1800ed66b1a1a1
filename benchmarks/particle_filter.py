"""Benchmark: bootstrap particle filter (numba) vs the same algorithm with NumPy stages.

Scenario: the bundled thesis LEO fast-spin case (pipelines/thesis/leo-ic1-fast-spin-controlled-1site.toml:
controlled 1U cube, Socorro, 73 epochs, r = 1 %), σθ = 60°, σω = 0.02°/s. Each size runs the robust filter with the
progressive correction ("progressive", which re-predicts the cloud at every tempering stage:
``predictions_per_particle`` counts those) and the plain bootstrap filter ("plain",
``progressive=False``), with numba at 1 and at ``--threads`` threads (thread scaling) and with
the NumPy stages (``run_bpf_numpy``, the reference; sizes up to ``--numpy-max``). Every
configuration runs in a fresh subprocess, after a small warm-up run that compiles / loads the
numba cache, so its peak resident memory (ru_maxrss: the whole process with the interpreter and
numba) is its own; the peak of traced Python/NumPy allocations (tracemalloc) is reported too.
Each configuration is timed ``--repeat`` times in its process (default 3): rates and CPU times
are the medians, ``particle_steps_per_s_best`` the best run; ``openmp_wait`` records the
OpenMP wait settings in force (:func:`lightcurve.threads.configure_threading`).

``--load K`` starts K CPU-bound processes (busy loops) before the measurements and stops them
after: the "under load" mode of the acceptance (K = 2 on 2 cores). ``--layer`` picks numba's
threading layer (workqueue, omp, tbb; each measured in its own subprocess).

``numba_threads`` is the thread count the configuration asks for; ``filter_threads`` the
threads the filter runs on (:func:`lightcurve.filters.bpf.bpf_threads`: a small cloud runs on
fewer).

Prints ONE JSON line: per configuration particle·steps per second (particles × epochs / filter
run time), run time and process CPU time, peak RSS (MB), traced peak (MB), final RSS attitude
error, speed-up over the NumPy run of the same size and mode (``speedup_vs_numpy``) and over
the 1-thread run (``thread_scaling``); plus the shared footer (wall time, cores, numba threads,
load average) and the affinity core count, the load processes and the threading layers.

Usage: python benchmarks/particle_filter.py [--particles 10000 100000] [--numpy-max 100000]
       [--threads 2] [--load 0] [--layer workqueue] [--modes progressive plain] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)

CHILD = r"""
import json, os, resource, sys, time, tracemalloc, warnings
warnings.simplefilter("ignore")
import numba
import numpy as np
from lightcurve._paths import data_dir
from lightcurve.studies.scenario import load_scenario
from lightcurve.studies.simulate import simulate
from lightcurve.filters import build_problem, run_bpf, run_bpf_numpy
from lightcurve.filters.bpf import bpf_threads

backend, N, prog, reps = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1", int(sys.argv[4])
sc = load_scenario(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")
lc = simulate(sc, 1)
prob = build_problem(lc, seed=0, sigma_theta_deg=60.0, sigma_omega_deg_s=0.02)
run = run_bpf if backend == "numba" else run_bpf_numpy
run(prob, particles=1000, seed=0, progressive=prog)   # warm-up: compile / load numba cache
walls, cpus, traced = [], [], 0.0
for _ in range(reps):
    tracemalloc.start()
    c0 = time.process_time()
    t0 = time.perf_counter()
    est = run(prob, particles=N, seed=0, progressive=prog)
    walls.append(time.perf_counter() - t0)
    cpus.append(time.process_time() - c0)
    traced = max(traced, tracemalloc.get_traced_memory()[1])
    tracemalloc.stop()
dt = float(np.median(walls))
rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(json.dumps({"backend": backend, "particles": N, "progressive": prog, "epochs": len(est),
                  "numba_threads": numba.get_num_threads(),
                  "filter_threads": (min(numba.get_num_threads(), bpf_threads(N))
                                     if backend == "numba" else 1),
                  "threading_layer": numba.threading_layer() if backend == "numba" else None,
                  "openmp_wait": {k: os.environ.get(k) for k in ("OMP_WAIT_POLICY",
                                                                 "GOMP_SPINCOUNT")},
                  "repeats": reps, "runtime_s": dt, "runtimes_s": walls,
                  "cpu_s": float(np.median(cpus)), "particle_steps_per_s": N * len(est) / dt,
                  "particle_steps_per_s_best": N * len(est) / min(walls),
                  "peak_rss_mb": rss_mb, "traced_peak_mb": traced / 2**20,
                  "final_att_error_rss_deg": est.summary()["final_att_error_rss_deg"],
                  "tempering_stages": int(np.sum(est.meta["tempering_stages"])),
                  "predictions_per_particle": len(est) + int(np.sum(est.meta["tempering_stages"])),
                  "load_avg_1min": os.getloadavg()[0]}))
"""

BUSY = "import time\nt = time.time()\nx = 0\nwhile True:\n    x += 1\n"


def _env(threads, layer):
    env = dict(os.environ)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    env["NUMBA_NUM_THREADS"] = str(int(threads))
    if layer:
        env["NUMBA_THREADING_LAYER"] = layer
        if layer == "tbb":   # pip's tbb puts libtbb.so.12 in <prefix>/lib, off the loader path
            lib = os.path.join(sys.prefix, "lib")
            env["LD_LIBRARY_PATH"] = lib + os.pathsep + env.get("LD_LIBRARY_PATH", "")
    return env


def _child(backend, n, progressive, threads, layer, repeat):
    out = subprocess.run([sys.executable, "-c", CHILD, backend, str(n),
                          "1" if progressive else "0", str(int(repeat))], capture_output=True,
                         text=True,
                         env=_env(threads, layer), check=False)
    if out.returncode:
        return {"backend": backend, "particles": n, "progressive": progressive,
                "threading_layer": layer, "error": out.stderr.strip().splitlines()[-1:]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, nargs="+", default=[10_000, 100_000])
    ap.add_argument("--numpy-max", type=int, default=100_000,
                    help="largest particle count also run with the NumPy reference")
    ap.add_argument("--threads", type=int, default=None,
                    help="numba threads of the parallel runs (default: the cores of the "
                         "affinity mask)")
    ap.add_argument("--load", type=int, default=0,
                    help="CPU-bound busy processes running during the measurements")
    ap.add_argument("--layer", nargs="+", default=[None],
                    help="numba threading layer(s) to measure (workqueue, omp, tbb; default: "
                         "numba's choice)")
    ap.add_argument("--modes", nargs="+", default=["progressive", "plain"],
                    choices=["progressive", "plain"])
    ap.add_argument("--repeat", type=int, default=3,
                    help="timed runs per configuration, in one process after the warm-up: "
                         "the rates use the median run time (the best is reported too)")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    threads = int(args.threads or cores)
    busy = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(args.load)]
    res = {"benchmark": "particle_filter", "affinity_cores": cores, "threads": threads,
           "load_processes": args.load, "runs": []}
    try:
        if busy:
            time.sleep(2.0)
        for n in args.particles:
            for mode in args.modes:
                prog = mode == "progressive"
                ref = _child("numpy", n, prog, 1, None, args.repeat) if n <= args.numpy_max else None
                if ref is not None:
                    ref["mode"] = mode
                    res["runs"].append(ref)
                for layer in args.layer:
                    one = _child("numba", n, prog, 1, layer, args.repeat) if threads > 1 else None
                    par = _child("numba", n, prog, threads, layer, args.repeat)
                    par["mode"] = mode
                    if ref is not None and "runtime_s" in par and "runtime_s" in ref:
                        par["speedup_vs_numpy"] = ref["runtime_s"] / par["runtime_s"]
                    if one is not None:
                        one["mode"] = mode
                        res["runs"].append(one)
                        if "runtime_s" in one and "runtime_s" in par:
                            par["thread_scaling"] = one["runtime_s"] / par["runtime_s"]
                    res["runs"].append(par)
    finally:
        for p in busy:
            p.kill()
            p.wait()
    print_with_machine(res, t_start)


if __name__ == "__main__":
    main()
