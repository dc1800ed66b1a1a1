"""Benchmark: full observation-geometry evaluation, one object, two sites, 10,000 epochs.

Prints one JSON line: epochs per second for ``compute_geometry`` (Sun ephemeris, GCRS→ITRS
rotations, site positions, alt/az, phase angle, airmass, conical eclipse, flags), and,
separately, for the J4 numerical orbit propagation that produces the object positions.
Run: ``python benchmarks/geometry.py``.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

try:  # run from a source checkout without installing
    import lightcurve  # noqa: F401
except ImportError:  # pragma: no cover
    import sys

    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def main(n: int = 10_000, repeats: int = 3) -> dict:
    from lightcurve.geometry.observation import compute_geometry
    from lightcurve.geometry.orbits import Orbit

    epoch = "2020-03-01T08:08:40Z"
    t = np.arange(n, dtype=float) * 1.0                 # 1 s cadence, 10,000 s
    site_index = (np.arange(n) // 100) % 2              # two sites alternating in blocks
    sites = ["socorro", "bear_lake"]
    orbit = Orbit.from_elements(6871.14e3, 0.01, np.radians(83), 0.0, 0.0, np.radians(126.264))
    orbit.positions(epoch, t[:10])                      # warm-up (numba compile/cache load)
    compute_geometry(epoch, t[:10], site_index[:10], sites, np.ones((10, 3)) * 7e6)

    t0 = time.perf_counter()
    r, v = orbit.positions(epoch, t)
    t_prop = time.perf_counter() - t0

    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        g = compute_geometry(epoch, t, site_index, sites, r, v)
        best = min(best, time.perf_counter() - t0)
    out = {
        "benchmark": "geometry",
        "n_epochs": n,
        "n_sites": 2,
        "geometry_seconds": round(best, 4),
        "geometry_epochs_per_s": round(n / best, 1),
        "propagation_J4_seconds": round(t_prop, 4),
        "propagation_epochs_per_s": round(n / t_prop, 1),
        "n_visible": int(g.visible.sum()),
        "cpu_count": os.cpu_count(),
    }
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
