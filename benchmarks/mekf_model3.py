"""Kalman-filter cost per epoch with and without reflection states (Bernard 2021 ch. 8).

Prints ONE JSON line: microseconds of filter time per epoch (``Estimate.runtime_s / N``,
median over ``--reps`` runs after one warm-up run that compiles / loads the numba cache) for

* ``mekf_attitude``   — MEKF, attitude and rate only (6 states);
* ``mekf_model1``     — MEKF + Model 1 constant site bias (7 states);
* ``mekf_model3``     — MEKF + Model 3 facet parameters of cube_1u (6 + 24 states);
* ``mekf_model3_known`` — MEKF, Model 3 with the attitude known (§10.7, 24 states);
* ``ukf_model3``      — UKF + Model 3 (for reference: 61 sigma points per step);

on Bernard's LEO IC1 fast-spin case (pipelines/thesis/leo-ic1-fast-spin-controlled-1site.toml,
cube_1u, 1 site, reflection parameters perturbed by 10 % as in §10.1; σθ = 3°), with
``cpu_count`` and the 1-minute load average before and after (the machine may be shared:
the numbers are wall-clock and scale with the load).

Usage: ``python benchmarks/mekf_model3.py [--reps 5] [--cases mekf_model3,ukf_model3]``
(run it under ``nice -n 10`` on a shared machine; set NUMBA_NUM_THREADS=1 there).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lightcurve._paths import data_dir  # noqa: E402
from lightcurve.filters.invert import invert  # noqa: E402
from lightcurve.studies.scenario import load_scenario  # noqa: E402
from lightcurve.studies.simulate import simulate  # noqa: E402

LEO = data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml"
REFL = '\n[reflection]\nperturb = true\nsigma_frac = 0.1\nparams = ["xi", "a", "m", "A"]\n'

CASES = {
    "mekf_attitude": dict(method="mekf", reflection="none"),
    "mekf_model1": dict(method="mekf", reflection="model1"),
    "mekf_model3": dict(method="mekf", reflection="model3"),
    "mekf_model3_known": dict(method="mekf", reflection="model3", attitude="truth"),
    "ukf_model3": dict(method="ukf", reflection="model3"),
}


def leo_curve(seed=1):
    """The LEO fast-spin lightcurve with §10.1 perturbed reflection parameters."""
    txt = LEO.read_text()
    txt = txt.replace("\n[effects]", REFL + "\n[effects]") if "[effects]" in txt else txt + REFL
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / LEO.name
        p.write_text(txt)
        sc = load_scenario(p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(sc, seed=seed)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--cases", default=",".join(CASES))
    a = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    curve = leo_curve()
    n = len(curve)
    res = {"benchmark": "mekf_model3", "cpu_count": os.cpu_count(), "epochs": n,
           "reps": a.reps, "load_avg_start": round(load0, 2),
           "env_threads": {v: os.environ.get(v) for v in ("NUMBA_NUM_THREADS",
                                                          "OPENBLAS_NUM_THREADS")}}
    us = {}
    for name in a.cases.split(","):
        kw = dict(CASES[name])
        method = kw.pop("method")
        invert(curve, method, seed=1, **kw)                     # warm-up (numba cache, imports)
        times = []
        for _ in range(a.reps):
            e = invert(curve, method, seed=1, **kw)
            times.append(e.runtime_s / n)
        us[name] = round(1e6 * float(np.median(times)), 1)
        us[name + "_min"] = round(1e6 * float(np.min(times)), 1)
    res["us_per_epoch"] = us
    res["wall_s"] = round(time.perf_counter() - t0, 1)
    res["load_avg_end"] = round(os.getloadavg()[0], 2)
    print(json.dumps(res))


if __name__ == "__main__":
    main()
