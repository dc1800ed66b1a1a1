"""Resampling throughput of lightcurve.estimation.particles.

Prints ONE JSON line: particles per second (best of several repeats, after a warm-up call that
triggers/loads the numba compilation) for systematic resampling at 1e4 and 1e5 particles,
through the public function (input checks + one uniform draw + the njit kernel) and the bare
kernel, with multinomial resampling and a plain NumPy systematic implementation
(cumsum + searchsorted) for comparison, and ``os.cpu_count()``.

Run: ``python benchmarks/resampling.py``
"""

from __future__ import annotations

import json
import os
import time

import sys
from pathlib import Path

import numpy as np

try:
    import lightcurve  # noqa: F401
except ImportError:  # run from a source checkout without installing
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from lightcurve.estimation.particles import (  # noqa: E402
    multinomial_resample,
    systematic_resample,
    systematic_resample_nb,
)


def numpy_systematic(w, rng):
    """Plain NumPy systematic resampling (reference for the speed comparison)."""
    n = w.size
    c = np.cumsum(w)
    c /= c[-1]
    u = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(c, u, side="right"), n - 1)


def best_rate(fn, n, repeats):
    fn()  # warm-up (numba compile or cache load)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n / best


def main():
    out = {"benchmark": "resampling", "cpu_count": os.cpu_count()}
    for n in (10_000, 100_000):
        rng = np.random.default_rng(0)
        w = rng.random(n)
        w /= w.sum()
        reps = 200 if n <= 10_000 else 50
        tag = f"{n:.0e}".replace("+0", "")
        out[f"systematic_particles_per_s_{tag}"] = best_rate(
            lambda: systematic_resample(w, rng), n, reps)
        out[f"systematic_kernel_particles_per_s_{tag}"] = best_rate(
            lambda: systematic_resample_nb(w, 0.5, n), n, reps)
        out[f"multinomial_particles_per_s_{tag}"] = best_rate(
            lambda: multinomial_resample(w, rng), n, reps)
        out[f"numpy_systematic_particles_per_s_{tag}"] = best_rate(
            lambda: numpy_systematic(w, rng), n, reps)
        # sanity: the kernel and the NumPy reference agree for the same uniform
        a = systematic_resample_nb(w, 0.5, n)
        c = np.cumsum(w)
        b = np.minimum(np.searchsorted(c / c[-1], (0.5 + np.arange(n)) / n, side="right"),
                       n - 1)
        out[f"agree_with_numpy_{tag}"] = bool(np.mean(a == b) > 0.999)
    print(json.dumps({k: (round(v, 1) if isinstance(v, float) else v) for k, v in out.items()}))


if __name__ == "__main__":
    main()
