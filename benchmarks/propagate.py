"""Throughput of the RK4 attitude propagation kernel (quaternion + body rate, torque-free).

Propagates 10,000 states (random attitudes and rates, asymmetric inertia) for a number of
0.1 s steps with ``lightcurve.dynamics.rk4_propagate_nb`` (numba, parallel over states) and
prints one JSON line: states·steps per second, wall time, peak memory, core and thread counts.
Usage: ``python benchmarks/propagate.py [--states N] [--steps K] [--repeat R]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
import tracemalloc

import sys

import numba
import numpy as np

try:
    from lightcurve.dynamics import rk4_propagate_nb
except ModuleNotFoundError:  # run from a source checkout without installing
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    from lightcurve.dynamics import rk4_propagate_nb


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=10_000)
    ap.add_argument("--steps", type=int, default=1_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    rng = np.random.default_rng(0)
    q = rng.normal(size=(args.states, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w = rng.normal(size=(args.states, 3)) * 0.05
    J = np.array([[12.0, 0.8, -0.5], [0.8, 21.0, 1.1], [-0.5, 1.1, 30.0]])
    Ji = np.linalg.inv(J)
    T = np.zeros(3)

    t0 = time.perf_counter()
    rk4_propagate_nb(q[:2].copy(), w[:2].copy(), J, Ji, 0.1, 1, T)  # compile / load cache
    compile_s = time.perf_counter() - t0

    best = np.inf
    tracemalloc.start()
    for _ in range(args.repeat):
        qq, ww = q.copy(), w.copy()
        t0 = time.perf_counter()
        rk4_propagate_nb(qq, ww, J, Ji, 0.1, args.steps, T)
        best = min(best, time.perf_counter() - t0)
    _, peak_traced = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    norm_err = float(np.max(np.abs(np.linalg.norm(qq, axis=1) - 1.0)))
    rate = args.states * args.steps / best
    print(json.dumps({
        "benchmark": "rk4_propagate_nb",
        "states": args.states,
        "steps": args.steps,
        "dt_s": 0.1,
        "best_wall_s": round(best, 4),
        "states_steps_per_s": round(rate, 1),
        "million_states_steps_per_s": round(rate / 1e6, 2),
        "compile_or_cache_load_s": round(compile_s, 3),
        "peak_python_alloc_MB": round(peak_traced / 2**20, 3),
        "peak_rss_MB": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "max_quat_norm_error": norm_err,
        "numba_threads": numba.get_num_threads(),
        "cpu_count": os.cpu_count(),
    }))


if __name__ == "__main__":
    main()
