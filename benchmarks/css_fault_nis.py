"""Per-sensor NIS statistics of the calibration filters on fault-free table 5.1/5.2 cases.

What the averaged-NIS fault detectors assume (O'Keefe 2015, eq. 5.5-5.11: ``K ε̄ ~ χ²_K``)
is that each sensor's scalar NIS ``ε = ν²/S`` is white with mean 1.  This script measures
both on the §4.4.3 case (``simulate_thesis_calibration_case``, no failure injected), for
each variant (thesis: §4.2 filter with its noise floor; robust: ours) and albedo grid:
per initialised sensor (an output above 0.4 once, §5.2), after 600 s,

* the mean of ε (1 for a consistent filter);
* its integrated autocorrelation time τ in samples (``emcee.autocorr.integrated_time``,
  window constant c = 5; 1 for white values): a K-sample average then carries about K/τ
  independent values, not K;
* the largest K-sample trailing average (K = the detector's window) against the variant's
  detection threshold — above it, a fault-free sensor is flagged (a false detection); for the
  robust variant the threshold follows the share of the innovation variance that the filter
  reports as correlated in time (the coarse grids' representation error,
  :meth:`~lightcurve.css.calibration.CalibrationResult.correlated_share`), so the largest
  ratio of average to threshold is reported as well, with the mean correlated share.

Reported: one row per variant and grid (median and largest over the sensors and runs), then
one JSON line with ``os.cpu_count()`` and the load average at the start.

Usage: python benchmarks/css_fault_nis.py [--runs 5] [--seed 0] [--controlled]
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np
from emcee.autocorr import integrated_time

from lightcurve.css.calibration import (calibration_filter_setup, initialised_sensors,
                                        run_calibration)
from lightcurve.css.fault import sensor_nis
from lightcurve.css.fault_tables import (THESIS_GRIDS, fault_table_case, robust_detectors,
                                         thesis_detector)


def sensor_stats(t, nis, init, det, share=None, t_start_s=600.0):
    """(mean, τ, largest window average, largest average / threshold, mean correlated share)
    of each initialised sensor's NIS after ``t_start_s``; ``det`` supplies the window and the
    threshold (:class:`AveragedNISDetector`), ``share`` (K,N) the correlated share of each
    innovation variance (None: none)."""
    after = t >= t_start_s
    avg = det.averages(nis)[after]
    lim = (np.broadcast_to(det.limit(), avg.shape) if share is None
           else np.asarray(det.limit(det.averages(share)))[after])
    out = []
    for j in np.flatnonzero(init):
        x = nis[after & np.isfinite(nis[:, j]), j]
        if x.size < 5 * det.window:
            continue
        tau = float(integrated_time(x, c=5, tol=0, quiet=True)[0])
        a = avg[:, j]
        sh = 0.0 if share is None else float(np.nanmean(share[after, j]))
        out.append((float(x.mean()), tau, float(np.nanmax(a)), float(np.nanmax(a / lim[:, j])),
                    sh))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5, help="fault-free cases (default 5)")
    ap.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    ap.add_argument("--controlled", action="store_true", help="table 5.2's Sun-pointing case")
    a = ap.parse_args()
    load = os.getloadavg()
    rows = {}
    for seed in range(a.seed, a.seed + a.runs):
        case, _ = fault_table_case(seed, controlled=a.controlled)
        init = initialised_sensors(case.Y)
        for v in ("thesis", "robust"):
            for grid in THESIS_GRIDS:
                prm, alb = calibration_filter_setup(v, grid, None)
                det = thesis_detector(grid) if v == "thesis" else robust_detectors()[0]
                res = run_calibration(case.css_nominal, case.t, case.Y, case.gyro, case.sun_N,
                                      case.lit, case.r_I_m, case.epoch_utc, params=prm,
                                      albedo=alb, q_star=case.q_star,
                                      star_valid=case.star_valid)
                st = sensor_stats(case.t, sensor_nis(res.innov, res.innov_var), init, det,
                                  None if v == "thesis" else res.correlated_share())
                r = rows.setdefault((v, grid), {"stats": [], "threshold": det.limit(),
                                                "window": det.window})
                r["stats"] += st
    print(f"{a.runs} fault-free runs ({'controlled' if a.controlled else 'tumbling'}), "
          f"seeds {a.seed}..{a.seed + a.runs - 1}; per initialised sensor after 600 s")
    print("| variant | grid | sensors | mean NIS: median / range | τ (samples): median / "
          "largest | window | threshold | largest window average: median / largest | "
          "correlated share: mean | largest average / threshold | sensors above the "
          "threshold |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    js = []
    for (v, grid), r in rows.items():
        s = np.array(r["stats"])
        m, tau, mx, ratio, sh = s[:, 0], s[:, 1], s[:, 2], s[:, 3], s[:, 4]
        above = int(np.sum(ratio > 1.0))
        print(f"| {v} | {grid} | {len(s)} | {np.median(m):.2f} / {m.min():.2f}–{m.max():.2f} | "
              f"{np.median(tau):.1f} / {tau.max():.1f} | {r['window']} | {r['threshold']:.2f} | "
              f"{np.median(mx):.2f} / {mx.max():.2f} | {np.mean(sh):.2f} | "
              f"{np.median(ratio):.2f} / {ratio.max():.2f} | {above} |")
        js.append({"variant": v, "grid": grid, "sensors": len(s),
                   "mean_nis_median": float(np.median(m)), "tau_median": float(np.median(tau)),
                   "tau_max": float(tau.max()), "window_avg_max": float(mx.max()),
                   "threshold": r["threshold"], "correlated_share_mean": float(np.mean(sh)),
                   "ratio_max": float(ratio.max()), "sensors_above": above})
    print(json.dumps({"runs": a.runs, "seed": a.seed, "controlled": a.controlled,
                      "cpu_count": os.cpu_count(), "loadavg_start": load, "rows": js}))


if __name__ == "__main__":
    main()
