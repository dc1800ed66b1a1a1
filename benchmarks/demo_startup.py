"""Cold and warm start of ``lightcurve demo`` (numba compilation versus the on-disk cache).

Copies the package and its data folders into a fresh temporary folder (so numba has no cache
there), then runs, each in a new process: ``demo`` (cold: compiles every kernel it needs),
``demo`` again (warm: loads the kernels from the cache; nothing is recompiled — counted with
NUMBA_DEBUG_CACHE), then in a second fresh copy ``warmup`` followed by ``demo`` (the README's
install line). Prints one JSON line: wall and CPU seconds of each run, the number of kernels
saved (compiled) and loaded per run, cores, numba threads and load.

    python benchmarks/demo_startup.py
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)

ROOT = Path(__file__).resolve().parents[1]


def _copy(dst: Path):
    for name in ("lightcurve", "pipelines", "shapes", "observatories"):
        shutil.copytree(ROOT / name, dst / name, ignore=shutil.ignore_patterns("__pycache__"))


def _run(copy: Path, args):
    env = {**os.environ, "PYTHONPATH": str(copy), "NUMBA_DEBUG_CACHE": "1", "MPLBACKEND": "Agg"}
    t0 = time.perf_counter()
    c0 = os.times()
    r = subprocess.run([sys.executable, "-m", "lightcurve", *args], cwd=copy, env=env,
                       capture_output=True, text=True)
    c1 = os.times()
    if r.returncode:
        raise SystemExit(f"lightcurve {' '.join(args)} failed: {r.stderr[-2000:]}")
    log = r.stdout + r.stderr
    return {"wall_s": round(time.perf_counter() - t0, 2),
            "cpu_s": round((c1.children_user - c0.children_user)
                           + (c1.children_system - c0.children_system), 2),
            "kernels_compiled": len(re.findall(r"\[cache\] data saved", log)),
            "kernels_loaded": len(re.findall(r"\[cache\] data loaded", log))}


def main():
    t0 = time.perf_counter()
    out = {"benchmark": "demo_startup"}
    with tempfile.TemporaryDirectory() as d:
        a, b = Path(d) / "a", Path(d) / "b"
        _copy(a)
        _copy(b)
        out["demo_cold"] = _run(a, ["demo", "-o", "out", "-q"])
        out["demo_warm"] = _run(a, ["demo", "-o", "out", "-q"])
        out["warmup_cold"] = _run(b, ["warmup", "-q"])
        out["demo_after_warmup"] = _run(b, ["demo", "-o", "out", "-q"])
    print_with_machine(out, t0)


if __name__ == "__main__":
    main()
