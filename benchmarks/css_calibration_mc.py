"""Monte Carlo of the CSS calibration filters (O'Keefe §4.4, tables 4.1 and 4.3).

Part 1 (table 4.1): ``--runs`` dispersed §4.4 cases (one orbit, tumbling, dual pyramid,
scale factors N(1, 0.3²), misalignments N(0, 2°²), built-in albedo); full and reduced filters.
Reported: share of sensors that saw the Sun meeting 3σ scale ≤ 0.05 and misalignment 3σ ≤ 2°,
share with errors inside 3σ, and the median final 3σ (thesis: 0.018 full vs 0.9 reduced).

Part 2 (table 4.3 trend): truth with the CERES 1° map, the full filter with the CERES 1°, 5°
and 10° maps (``--runs-43`` cases; skipped without ../shared/data): median final 3σ and RMS
error of scale factors and misalignments per filter resolution.

Part 2 also runs the 5° and 10° filters with the albedo-grid representation error added to
R (:func:`lightcurve.css.calibration.albedo_grid_error`) and reports the pooled NEES / NMEE of
the final scale factors and misalignments against their 99 % χ² / normal bounds.

Part 3 (``--runs-star``): O'Keefe §4.1-4.2 leave the star tracker's rate and accuracy open
(we chose one every 10 s); the full and
reduced filters are re-run with it every 60 s, 300 s and without it.

Prints one JSON line (with os.cpu_count()).  Usage: python benchmarks/css_calibration_mc.py
[--runs 20] [--runs-43 5] [--runs-star 0] [--star-periods 10 60 300 0]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from lightcurve._paths import shared_data_dir
from lightcurve.css.albedo import load_albedo_map
from lightcurve.css.calibration import (AlbedoCells, CalibrationParams, acceptance_summary,
                                        run_calibration, simulate_calibration_case)


def _run(case, params, albedo="builtin"):
    res = run_calibration(case.css_nominal, case.t, case.Y, case.gyro, case.sun_N, case.lit,
                          case.r_I_m, case.epoch_utc, params=params.for_gyro(case.info["spec"]),
                          albedo=albedo, q_star=case.q_star, star_valid=case.star_valid)
    return acceptance_summary(case, res)


def part1(n):
    acc = {"full": [], "reduced": []}
    for i in range(n):
        case = simulate_calibration_case(np.random.SeedSequence([41, i]))
        for name, prm in (("full", CalibrationParams()), ("reduced", CalibrationParams.reduced())):
            s = _run(case, prm)
            saw = s["saw_sun"]
            acc[name].append({
                "scale3": s["scale_3sigma"][saw], "mis3": s["mis_3sigma_deg"][saw].max(axis=1),
                "inside": (np.abs(s["scale_err"]) <= s["scale_3sigma"])[saw]
                & np.all(np.abs(s["mis_err_deg"]) <= s["mis_3sigma_deg"], axis=1)[saw],
                "expo": s["exposure_s"][saw]})
    out = {}
    for name, rows in acc.items():
        s3 = np.concatenate([r["scale3"] for r in rows])
        m3 = np.concatenate([r["mis3"] for r in rows])
        ins = np.concatenate([r["inside"] for r in rows])
        ex = np.concatenate([r["expo"] for r in rows])
        well = ex >= 300.0
        out[name] = {"sensors": int(s3.size),
                     "scale_3sigma_median": float(np.median(s3)),
                     "mis_3sigma_deg_median": float(np.median(m3)),
                     "share_scale_ok": float(np.mean(s3 <= 0.05)),
                     "share_mis_ok": float(np.mean(m3 <= 2.0)),
                     "share_both_ok": float(np.mean((s3 <= 0.05) & (m3 <= 2.0))),
                     "share_both_ok_exposure_300s": float(np.mean(((s3 <= 0.05) & (m3 <= 2.0))[well])),
                     "share_errors_inside_3sigma": float(np.mean(ins))}
    return out


def _consistency(se, s3, me, m3):
    """Pooled final-state consistency of scale factors and misalignments (eq. 5.1-5.11):
    averaged NEES of the n scalar components (e²/σ², each χ²₁) against the two-sided 99 %
    χ² interval of an average of n, NMEE (mean e/σ) against ±z/√n, and the share inside 3σ."""
    from lightcurve.estimation.consistency import chi2_interval, nmee_interval

    e = np.concatenate([se, me])
    sg = np.concatenate([s3, m3]) / 3.0
    z = e / sg
    n = z.size
    lo, hi = chi2_interval(1, 0.99, n)
    nlo, nhi = nmee_interval(n, 0.99)
    return {"n": int(n), "nees": float(np.mean(z * z)), "nees_bounds_99": [lo, hi],
            "nees_inside": bool(lo <= np.mean(z * z) <= hi),
            "nmee": float(np.mean(z)), "nmee_bounds_99": [nlo, nhi],
            "nmee_inside": bool(nlo <= np.mean(z) <= nhi),
            "share_inside_3sigma": float(np.mean(np.abs(z) <= 3.0)),
            "share_scale_inside_3sigma": float(np.mean(np.abs(se) <= s3)),
            "share_mis_inside_3sigma": float(np.mean(np.abs(me) <= m3))}


def part2(n):
    """Table 4.3: truth CERES 1°, filter CERES 1°/5°/10°, each without and with the
    albedo-grid representation error in R (k, a from calibration.albedo_grid_error)."""
    from lightcurve.css.calibration import albedo_grid_error

    d = shared_data_dir()
    if d is None:
        return {"skipped": "../shared/data not available"}
    base = d / "earth_albedo"
    maps = {r: load_albedo_map(base / f"Earth_ALB_2018_CERES_All_{r}x{r}.csv") for r in (1, 5, 10)}
    cells = {r: AlbedoCells.from_map(m) for r, m in maps.items()}
    grid_err = {r: albedo_grid_error(cells[r], cells[1]) for r in (5, 10)}
    grid_err[1] = (0.0, 0.0)
    variants = [(r, False) for r in (1, 5, 10)] + [(5, True), (10, True)]
    rows = {v: [] for v in variants}
    for i in range(n):
        case = simulate_calibration_case(np.random.SeedSequence([43, i]), albedo_truth=maps[1])
        for (r, with_err) in variants:
            k, a = grid_err[r] if with_err else (0.0, 0.0)
            prm = CalibrationParams(albedo_grid_frac=k, albedo_grid_floor=a)
            s = _run(case, prm, cells[r])
            saw = s["saw_sun"]
            rows[(r, with_err)].append((s["scale_3sigma"][saw], s["scale_err"][saw],
                                        s["mis_3sigma_deg"][saw].ravel(),
                                        s["mis_err_deg"][saw].ravel()))
    out = {"grid_error_k_a": {f"{r}deg": list(v) for r, v in grid_err.items()}}
    for (r, with_err), rr in rows.items():
        s3 = np.concatenate([a for a, _, _, _ in rr])
        se = np.concatenate([b for _, b, _, _ in rr])
        m3 = np.concatenate([c for _, _, c, _ in rr])
        me = np.concatenate([e for _, _, _, e in rr])
        out[f"{r}deg" + ("_grid_error" if with_err else "")] = {
            "scale_3sigma_median": float(np.median(s3)),
            "scale_err_rms": float(np.sqrt(np.mean(se ** 2))),
            "mis_3sigma_deg_median": float(np.median(m3)),
            "mis_err_deg_rms": float(np.sqrt(np.mean(me ** 2))),
            "share_errors_inside_3sigma": float(np.mean(np.abs(se) <= s3)),
            "consistency": _consistency(se, s3, me, m3)}
    return out


def part3(n, periods):
    """Star-tracker dependence (our choice: one every 10 s; §4.1-4.2 leave it open): full and reduced filters with
    the star tracker every P s (0: none; the filter then starts from the true attitude)."""
    out = {}
    for per in periods:
        acc = {"full": [], "reduced": [], "reduced_constant_bias": []}
        for i in range(n):
            case = simulate_calibration_case(np.random.SeedSequence([41, i]), star_period_s=per)
            q0 = case.q_true[0] if per <= 0 else None
            # reduced_constant_bias: the considered albedo bias held constant over the orbit
            # (consider_tau_s = 0 switches the Gauss-Markov decay off) instead of decorrelating
            # every 300 s — the bias can then not be averaged out
            for name, prm in (("full", CalibrationParams()),
                              ("reduced", CalibrationParams.reduced()),
                              ("reduced_constant_bias",
                               CalibrationParams.reduced(consider_tau_s=0.0))):
                res = run_calibration(case.css_nominal, case.t, case.Y, case.gyro, case.sun_N,
                                      case.lit, case.r_I_m, case.epoch_utc,
                                      params=prm.for_gyro(case.info["spec"]),
                                      q_star=case.q_star, star_valid=case.star_valid, q0=q0)
                s = acceptance_summary(case, res)
                saw = s["saw_sun"]
                acc[name].append((s["scale_3sigma"][saw], s["mis_3sigma_deg"][saw].max(axis=1),
                                  (np.abs(s["scale_err"]) <= s["scale_3sigma"])[saw],
                                  float(np.percentile(s["attitude_err_deg"][600:], 50))))
        row = {}
        for name, rr in acc.items():
            s3 = np.concatenate([a for a, _, _, _ in rr])
            m3 = np.concatenate([b for _, b, _, _ in rr])
            ins = np.concatenate([c for _, _, c, _ in rr])
            row[name] = {"sensors": int(s3.size), "scale_3sigma_median": float(np.median(s3)),
                         "mis_3sigma_deg_median": float(np.median(m3)),
                         "share_both_ok": float(np.mean((s3 <= 0.05) & (m3 <= 2.0))),
                         "share_scale_inside_3sigma": float(np.mean(ins)),
                         "attitude_err_deg_median": float(np.median([d for *_, d in rr]))}
        out[f"star_{per:g}s" if per > 0 else "no_star_tracker"] = row
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--runs-43", type=int, default=5)
    ap.add_argument("--runs-star", type=int, default=0,
                    help="runs per star-tracker period of part 3 (0: skip)")
    ap.add_argument("--star-periods", type=float, nargs="+", default=[10.0, 60.0, 300.0, 0.0])
    a = ap.parse_args()
    t0 = time.time()
    res = {"benchmark": "css_calibration_mc", "cpu_count": os.cpu_count(),
           "table_4_1": part1(a.runs) if a.runs else None,
           "table_4_3": part2(a.runs_43) if a.runs_43 else None,
           "star_tracker": part3(a.runs_star, a.star_periods) if a.runs_star else None,
           "thesis_table_4_1_scale_3sigma": {"full": 0.018, "reduced": 0.9}}
    res["wall_s"] = round(time.time() - t0, 1)
    print(json.dumps(res))


if __name__ == "__main__":
    main()
