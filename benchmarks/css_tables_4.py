"""O'Keefe (2015) Tables 4.1-4.3 with the thesis-variant calibration filters (§4.2-4.3): final
3σ of the CSS scale factors and misalignments after one orbit, largest and smallest over the
initialised sensors, for the full filter with the 1°×1.25°, 5°×5° and 10°×10° TOMS grids and
for the reduced filter; one fixed case (the tables) and the mean over ``--runs`` Monte Carlo
cases (figs. 4.4, 4.7, 4.10: 300 runs in the thesis); our robust filters on the same cases
under the ``*_robust`` keys.

Run:  python benchmarks/css_tables_4.py [--runs 0] [--seed 4] [--configs dual_pyramid,cube]
                                      [--workers 1]
Prints ONE JSON line (shared footer: wall time, cores, numba threads, load); a progress bar
on stderr while the Monte Carlo cases run.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
try:  # run from a source checkout without installing
    import lightcurve  # noqa: F401
except ImportError:  # pragma: no cover
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=0, help="Monte Carlo cases (thesis: 300)")
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--configs", default="dual_pyramid,cube")
    ap.add_argument("--filters", default="1p25x1,5x5,10x10,reduced")
    ap.add_argument("--workers", type=int, default=1,
                    help="local processes for the Monte Carlo cases (numba threads sized so "
                         "that workers x threads <= cores)")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    from tqdm import tqdm

    from lightcurve.css.calibration import (simulate_thesis_calibration_case,
                                            thesis_calibration_monte_carlo,
                                            thesis_calibration_table)
    from lightcurve.css.okeefe2015 import THESIS_RESULTS

    filters = tuple(a.filters.split(","))
    out = {"benchmark": "css_tables_4", "seed": a.seed, "runs": a.runs, "workers": a.workers,
           "thesis": {k: THESIS_RESULTS[k] for k in ("table4_1", "table4_2", "table4_3")}}
    for conf in a.configs.split(","):
        fl = filters if conf == "dual_pyramid" else tuple(f for f in filters
                                                           if f in ("1p25x1", "reduced"))
        case = simulate_thesis_calibration_case(np.random.SeedSequence([a.seed, 0]), conf)
        out[f"{conf}_case"] = thesis_calibration_table(case, fl)
        out[f"{conf}_case_robust"] = thesis_calibration_table(case, fl, variant="robust")
        if a.runs > 0:
            with tqdm(total=a.runs, desc=f"{conf} cases", file=sys.stderr) as bar:
                mc = thesis_calibration_monte_carlo(conf, fl, a.runs, seed=a.seed,
                                                    workers=a.workers, progress=bar.update)
            out[f"{conf}_mc_mean"] = _mc_mean(mc["thesis"])
            out[f"{conf}_mc_mean_robust"] = _mc_mean(mc["robust"])
    print_with_machine(out, t0)


def _mc_mean(acc):
    """Mean over the runs of each filter's table entries (largest, smallest)."""
    keys = ("c", "theta_deg", "phi_deg", "mean_theta_phi_deg")
    return {f: {k: [float(np.mean([r[k][0] for r in v])), float(np.mean([r[k][1] for r in v]))]
                for k in keys} | {"inside_3sigma": float(np.mean([r["inside_3sigma"] for r in v]))}
            for f, v in acc.items()}

if __name__ == "__main__":
    main()
