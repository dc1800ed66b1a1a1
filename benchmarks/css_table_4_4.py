"""O'Keefe (2015) table 4.4: time per call of the calibration filters' propagation and
measurement updates over one simulated §4.4 case.

The thesis (§4.4.3): a 3460 s simulation with no control effort, "the propagation update is
called 34601 times and the estimation update 6921 times" (10 Hz gyro, 2 Hz CSS), timed for the
full calibration filter with the 1°×1.25°, 5°×5° and 10°×10° TOMS albedo grids and for the
reduced filter, averages ± standard deviations in µs (C on a 2.5 GHz i7):

    full 1°×1.25°  15.4 ± 2.7 / 6141 ± 1470     full 5°×5°  15.1 ± 2.9 / 506 ± 101
    full 10°×10°   15.0 ± 2.9 /  180 ± 19.7     reduced     18.3 ± 3.8 / 183 ± 24.5

Here: one thesis-variant §4.4 case (``simulate_thesis_calibration_case``: tumbling dual
pyramid, intermediate gyro at 10 Hz, CSS at 2 Hz, TOMS 1°×1.25° albedo in the truth) of
3460 s, run once per filter (``lightcurve.css.calibration.thesis_filter_setup``) with
per-call timing (``run_calibration(..., timings=...)``); the albedo model is ON in the three
full filters (their measurement model sums the grid) and OFF in the reduced one (albedo as
a measurement bias), as in the thesis. A first run per filter compiles the kernels and is
not timed. Times are wall-clock of Python calls into numba kernels (≈ 1–3 µs of call
overhead each), not of C.

Prints ONE JSON line: per filter the call counts and mean ± sd (and median) µs of each
update, the thesis's numbers, the ratios of the measurement updates to the reduced filter's
(ours and the thesis's), and the shared footer (wall time, cores, numba threads, load).

Usage: python benchmarks/css_table_4_4.py [--seed 4] [--duration-s 3460]
Needs the TOMS files in ../shared/data (the thesis's albedo data).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)

from lightcurve.css.okeefe2015 import THESIS_RESULTS  # noqa: E402

THESIS_TABLE_4_4 = THESIS_RESULTS["table4_4"]  # ((propagation mean, sd), (update mean, sd)) µs


def _stats(x):
    x = np.asarray(x, float)
    return {"calls": int(x.size), "mean_us": float(x.mean()), "sd_us": float(x.std(ddof=1)),
            "median_us": float(np.median(x))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=4, help="case seed (default 4)")
    ap.add_argument("--duration-s", type=float, default=3460.0,
                    help="simulated time, s (default 3460, §4.4.3)")
    a = ap.parse_args(argv)
    from lightcurve.css.calibration import (run_calibration, simulate_thesis_calibration_case,
                                            thesis_filter_setup)

    t0 = time.perf_counter()
    case = simulate_thesis_calibration_case(a.seed, duration_s=a.duration_s)
    out = {"benchmark": "css_table_4_4", "seed": a.seed, "duration_s": a.duration_s,
           "filters": {}}
    for name in THESIS_TABLE_4_4:
        prm, alb = thesis_filter_setup(name)

        def run(timings=None):
            return run_calibration(case.css_nominal, case.t, case.Y, case.gyro, case.sun_N,
                                   case.lit, case.r_I_m, case.epoch_utc, params=prm,
                                   albedo=alb, q_star=case.q_star, star_valid=case.star_valid,
                                   timings=timings)

        run()                       # compile / load the kernels, fill the caches
        tm = {}
        run(tm)
        (tp, sp), (tu, su) = THESIS_TABLE_4_4[name]
        out["filters"][name] = {
            "albedo_model": name != "reduced",
            "propagation": _stats(tm["propagation_us"]),
            "update": _stats(tm["update_us"]),
            "thesis": {"propagation_mean_us": tp, "propagation_sd_us": sp,
                       "update_mean_us": tu, "update_sd_us": su}}
    ref = out["filters"]["reduced"]["update"]["mean_us"]
    for name, f in out["filters"].items():
        f["update_vs_reduced"] = f["update"]["mean_us"] / ref
        f["thesis_update_vs_reduced"] = THESIS_TABLE_4_4[name][1][0] / THESIS_TABLE_4_4["reduced"][1][0]
    print_with_machine(out, t0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
