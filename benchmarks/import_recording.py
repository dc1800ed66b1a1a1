"""Benchmark: reading a 10 Hz observatory CSV (two objects, two cameras, alt/az + range).

Prints one JSON line: rows, rows per second of :func:`lightcurve.io.recording.read_recordings`
(CSV parsing, sorting, topocentric → GCRS positions, Sun/site geometry, screening) and the
shared footer (wall time, cores, numba threads, load). Run:
``python benchmarks/import_recording.py [ROWS]`` (default 100,000).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
import warnings
from datetime import datetime, timedelta, timezone

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
try:  # run from a source checkout without installing
    import lightcurve  # noqa: F401
except ImportError:  # pragma: no cover
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)


def write_csv(path, n_rows: int) -> None:
    """n_rows rows at 10 Hz: 2 objects x 2 cameras share each instant; smooth made-up tracks."""
    t0 = datetime(2022, 3, 21, 2, 0, tzinfo=timezone.utc)
    n_t = n_rows // 4
    k = np.arange(n_t)
    lines = ["utc,object,camera,site,mag,mag_sigma,alt_deg,az_deg,range_m"]
    for j in range(n_t):
        stamp = (t0 + timedelta(seconds=0.1 * j)).strftime("%Y-%m-%dT%H:%M:%S.%f")
        for obj, off in (("A", 0.0), ("B", 5.0)):
            alt = 30.0 + 20.0 * np.sin(2e-4 * k[j]) + off
            az = (100.0 + 0.01 * k[j]) % 360.0
            for cam in ("c1", "c2"):
                lines.append(f"{stamp},{obj},{cam},mount_lemmon,6.0,0.05,{alt:.6f},{az:.6f},1200000.0")
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def main(n_rows: int = 100_000) -> dict:
    from lightcurve.io.recording import read_recordings

    with tempfile.TemporaryDirectory() as d:
        f = os.path.join(d, "track.csv")
        write_csv(f, 400)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            read_recordings(f, unlit="keep")                   # warm-up (ephemeris, caches)
        write_csv(f, n_rows)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = read_recordings(f, unlit="keep")
        dt = time.perf_counter() - t0
    rows = sum(len(v) for v in out.values())
    return {"benchmark": "import_recording", "rows": rows, "files": len(out),
            "runtime_s": dt, "rows_per_s": rows / dt}


if __name__ == "__main__":
    t_start = time.perf_counter()
    print_with_machine(main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000), t_start)
