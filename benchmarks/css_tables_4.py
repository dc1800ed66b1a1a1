"""O'Keefe (2015) Tables 4.1-4.3 with the thesis-variant calibration filters (§4.2-4.3): final
3σ of the CSS scale factors and misalignments after one orbit, largest and smallest over the
initialised sensors, for the full filter with the 1°×1.25°, 5°×5° and 10°×10° TOMS grids and
for the reduced filter; one fixed case (the tables) and the mean over ``--runs`` Monte Carlo
cases (figs. 4.4, 4.7, 4.10: 300 runs in the thesis); our robust filters on the same cases
under the ``*_robust`` keys.

Run:  python benchmarks/css_tables_4.py [--runs 0] [--seed 4] [--configs dual_pyramid,cube]
Prints ONE JSON line (shared footer: wall time, cores, numba threads, load).
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
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    from lightcurve.css.calibration import (simulate_thesis_calibration_case,
                                            thesis_calibration_table)
    from lightcurve.css.okeefe2015 import THESIS_RESULTS

    filters = tuple(a.filters.split(","))
    out = {"benchmark": "css_tables_4", "seed": a.seed, "runs": a.runs,
           "thesis": {k: THESIS_RESULTS[k] for k in ("table4_1", "table4_2", "table4_3")}}
    for conf in a.configs.split(","):
        fl = filters if conf == "dual_pyramid" else tuple(f for f in filters
                                                           if f in ("1p25x1", "reduced"))
        case = simulate_thesis_calibration_case(np.random.SeedSequence([a.seed, 0]), conf)
        out[f"{conf}_case"] = thesis_calibration_table(case, fl)
        out[f"{conf}_case_robust"] = thesis_calibration_table(case, fl, variant="robust")
        if a.runs > 0:
            acc = {f: [] for f in fl}
            acc_r = {f: [] for f in fl}
            for i in range(a.runs):
                c = simulate_thesis_calibration_case(np.random.SeedSequence([a.seed, 1 + i]), conf)
                tab = thesis_calibration_table(c, fl)
                tab_r = thesis_calibration_table(c, fl, variant="robust")
                for f in fl:
                    acc[f].append(tab[f])
                    acc_r[f].append(tab_r[f])
            for key, acc_v in ((f"{conf}_mc_mean", acc), (f"{conf}_mc_mean_robust", acc_r)):
                out[key] = _mc_mean(acc_v)
    print_with_machine(out, t0)


def _mc_mean(acc):
    """Mean over the runs of each filter's table entries (largest, smallest)."""
    keys = ("c", "theta_deg", "phi_deg", "mean_theta_phi_deg")
    return {f: {k: [float(np.mean([r[k][0] for r in v])), float(np.mean([r[k][1] for r in v]))]
                for k in keys} | {"inside_3sigma": float(np.mean([r["inside_3sigma"] for r in v]))}
            for f, v in acc.items()}

if __name__ == "__main__":
    main()
