"""O'Keefe (2015) tables 5.1-5.2 and fig. 5.5: fault detection on the §4.4 calibration case.

The thesis's experiment (§5.2, with the §4.4.3 parameters): one orbit of the dual pyramid,
tumbling (table 5.1) or keeping +Z on the Sun (table 5.2); CSS 1 fails at 1950 s — off
(output 0), stuck (output held at its value at the failure) or random (uniform on [0, 1]);
the full calibration filter runs with the 1°×1.25°, 5°×5° or 10°×10° TOMS grid, and a sensor
is reported failed when its 100-sample averaged NIS exceeds 3.0, 1.2 or 1.2 (§5.2).

Counting (the text under tables 5.1-5.2): runs in which CSS 1 never reads above the
direct-sunlight threshold 0.4 (it is never initialised in the filter) are removed from the
correct detections; a false detection is a reported failure of any of CSS 2-8, or of CSS 1
before the failure.  The denominators of the thesis's false detections (3686 of 500 runs,
about 7.4 per run) count the initialised sensors of all runs, CSS 1 included; ours do the
same.

Each run simulates one truth (:func:`~lightcurve.css.calibration.simulate_thesis_calibration_case`)
and fails CSS 1 in each mode on copies of its outputs, so the three modes and the three grids
of one run fly the same spacecraft (in the thesis, the random failure also changed the
albedo's random numbers; §5.2.2).  Two variants run on the same data:

* ``thesis``: the §4.2 filter as written (:meth:`CalibrationParams.thesis_full`) and the
  §5.2 detector (window 100 valid samples, the thresholds above).  §5.1 leaves open what
  happens before a sensor's window is full: no decision until 100 values are averaged.
* ``robust``: our calibration filter (:func:`~lightcurve.css.calibration.robust_filter_setup`)
  with our detectors — the χ²-bounded averaged NIS of
  :class:`~lightcurve.css.fault.AveragedNISDetector` (its bound widened by the share of
  each innovation variance that the filter reports as the grid's time-correlated
  representation error, :meth:`~lightcurve.css.calibration.CalibrationResult.correlated_share`)
  and the
  :class:`~lightcurve.css.fault.DarkSensorDetector` (CSS noise 0.05 of §2.4).

Fig. 5.5 compares the averaged NIS of nominal and failed sensors: per run we keep the largest
averaged NIS of each healthy initialised sensor (CSS 2-8; over the run) and of CSS 1 after the
failure — the two quantities a threshold has to separate.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..estimation.rng import as_generator
from .fault import (FAULT_MODES, AveragedNISDetector, DarkSensorDetector, inject_fault,
                    sensor_nis)

__all__ = ["THESIS_GRIDS", "EXPERIMENTS", "VARIANTS", "thesis_detector", "robust_detectors",
           "thesis_filter_overrides", "fault_table_case", "fault_table_run", "fault_table_study", "summarise",
           "plot_fault_nis"]

THESIS_GRIDS = ("1p25x1", "5x5", "10x10")
"""The on-board albedo grids of §5.2 (TOMS 1°×1.25°, 5°×5°, 10°×10°)."""

EXPERIMENTS = {"table5_1": False, "table5_2": True}
"""Experiment name → controlled (table 5.1: tumbling; table 5.2: Sun-pointing)."""

VARIANTS = ("thesis", "robust")


def thesis_detector(grid: str) -> AveragedNISDetector:
    """§5.2's detector for the filter with albedo grid ``grid``: 100-sample averaged NIS
    above 3.0 (1°×1.25°) or 1.2 (5°×5°, 10°×10°), decisions from the start of the run."""
    from .okeefe2015 import FAULT

    return AveragedNISDetector(window=int(FAULT["window"]),
                               threshold=float(FAULT["threshold"][grid]), t_start_s=0.0)


def robust_detectors():
    """Our detectors on the thesis case: averaged NIS (defaults of
    :class:`AveragedNISDetector`) and the dark-sensor test with the §2.4 CSS noise."""
    from .okeefe2015 import CSS_SIM

    return AveragedNISDetector(), DarkSensorDetector(sigma_noise=float(CSS_SIM["noise_sigma"]))


def _max_or_nan(v) -> float:
    v = np.asarray(v, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.max()) if v.size else float("nan")


def thesis_filter_overrides(overrides) -> dict:
    """Check ``overrides`` (name → value, command-line strings or typed values) against the
    fields of :class:`~lightcurve.css.calibration.CalibrationParams` (an ablation of the
    thesis filter, e.g. ``{"fov_edge_margin": 0.03}``, ``{"skip_in_shadow": True}`` or
    ``{"floor_rule": "predicted"}``); returns them with the fields' types."""
    from ..io.tomlio import field_types, typed_overrides
    from .calibration import FLOOR_RULES, CalibrationParams

    return typed_overrides(overrides, field_types(CalibrationParams, exclude=("thesis",)),
                           field="thesis_filter", what="calibration-filter setting",
                           choices={"floor_rule": FLOOR_RULES}, from_text=True)


def fault_table_case(seed, *, controlled=False, duration_s=None):
    """The simulated §4.4.3 case of :func:`fault_table_run` for ``seed`` (table 5.1:
    ``controlled`` False, 5.2: True) and the generator that draws its failures; the case is
    the same for every variant, grid and failure mode of that run."""
    from .calibration import simulate_thesis_calibration_case

    g_case, g_fail = as_generator(seed).spawn(2)
    case = simulate_thesis_calibration_case(g_case, duration_s=duration_s,
                                            controlled=controlled)
    return case, g_fail


def fault_table_run(seed, *, controlled=False, grids=THESIS_GRIDS, modes=FAULT_MODES,
                    variants=VARIANTS, duration_s=None, albedo_dir=None,
                    thesis_filter=None) -> dict:
    """One run of table 5.1 (``controlled`` False) or 5.2: simulate the case, fail CSS 1 in
    each mode, run each variant's filter and detector with each grid; ``thesis_filter``:
    overrides of the thesis filter's settings (:func:`thesis_filter_overrides`, ablations).

    Returns a dict: ``initialised`` {mode: (N,) bool, outputs above 0.4 once}, and per
    variant, grid and mode ``{"false": [flagged sensors], "detected": bool, "ttd_s":
    delay of the first flag of CSS 1 after the failure (None if none), "ttd_eval_s": delay
    from CSS 1's first evaluated sample after the failure (None), "css1_max_avg": largest
    averaged NIS of CSS 1 after the failure, "healthy_max_avg": [largest averaged NIS of each
    initialised CSS 2-N]}`` (NaN where none).
    """
    from .calibration import calibration_filter_setup, initialised_sensors, run_calibration
    from .okeefe2015 import FAULT

    case, g_fail = fault_table_case(seed, controlled=controlled, duration_s=duration_s)
    s = int(FAULT["sensor"])
    t_fail = float(FAULT["t_fail_s"])
    after = case.t >= t_fail
    kf = int(np.searchsorted(case.t, t_fail))
    out = {"initialised": {}, "gain_true_css1": float(case.scale_true[s])}
    mode_rngs = dict(zip(modes, g_fail.spawn(len(modes))))
    data = {}
    for m in modes:
        Y = inject_fault(case.Y, case.t, s, m, t_fail, mode_rngs[m])
        init = initialised_sensors(Y)
        data[m] = (Y, init)
        out["initialised"][m] = init.tolist()
    for v in variants:
        out[v] = {}
        for grid in grids:
            prm, alb = calibration_filter_setup(v, grid, albedo_dir)
            if v == "thesis":
                if thesis_filter:
                    prm = replace(prm, **thesis_filter)
                det, dark = thesis_detector(grid), None
            else:
                det, dark = robust_detectors()
            out[v][grid] = {}
            for m in modes:
                Y, init = data[m]
                res = run_calibration(case.css_nominal, case.t, Y, case.gyro, case.sun_N,
                                      case.lit, case.r_I_m, case.epoch_utc, params=prm,
                                      albedo=alb, q_star=case.q_star,
                                      star_valid=case.star_valid)
                nis = sensor_nis(res.innov, res.innov_var)
                avg = det.averages(nis)
                F = det.flags(case.t, nis, None if v == "thesis" else res.correlated_share())
                if dark is not None:
                    F |= dark.flags(case.t, Y, res.u_model)
                F &= init[None, :]
                false = [int(k) for k in range(Y.shape[1])
                         if (F[:, k].any() if k != s else F[~after, k].any())]
                hit = np.flatnonzero(F[:, s] & after)
                ev = np.flatnonzero(np.isfinite(nis[:, s]) & after)
                ttd = float(case.t[hit[0]] - t_fail) if hit.size else None
                ttd_ev = (float(case.t[hit[0]] - case.t[ev[0]])
                          if hit.size and ev.size else None)
                out[v][grid][m] = {
                    "false": false, "detected": bool(hit.size) and bool(init[s]),
                    "ttd_s": ttd, "ttd_eval_s": ttd_ev,
                    "css1_max_avg": _max_or_nan(avg[kf:, s]),
                    "healthy_max_avg": [_max_or_nan(avg[:, k]) for k in range(Y.shape[1])
                                        if k != s and init[k]],
                }
    return out


def _worker(arg):
    import time

    seed, kw = arg
    c0 = time.process_time()
    out = fault_table_run(seed, **kw)
    out["cpu_s"] = time.process_time() - c0
    return out


def _pct(v, qs=(10, 50, 90, 99)):
    v = np.asarray([x for x in v if x is not None and np.isfinite(x)], dtype=float)
    if not v.size:
        return None
    d = {f"p{q}": float(np.percentile(v, q)) for q in qs}
    d.update(mean=float(v.mean()), max=float(v.max()), n=int(v.size))
    return d


def summarise(runs, *, grids=THESIS_GRIDS, modes=FAULT_MODES, variants=VARIANTS) -> dict:
    """Tables 5.1/5.2 from :func:`fault_table_run` records: per variant, grid and mode
    ``false`` / ``false_total`` (reported failures among the initialised sensors of all runs,
    CSS 1 counted before the failure only) and ``correct`` / ``total`` (runs with CSS 1
    initialised and flagged after the failure), time to detection statistics (s, from the
    failure and from CSS 1's first evaluated sample after it), and fig. 5.5's averaged-NIS
    statistics (largest per healthy sensor; CSS 1 after the failure), with the raw values
    under ``nis`` for plots."""
    from .okeefe2015 import FAULT

    s = int(FAULT["sensor"])
    res = {}
    for v in variants:
        res[v] = {}
        for grid in grids:
            row = {}
            healthy = []
            for m in modes:
                recs = [(r["initialised"][m], r[v][grid][m]) for r in runs]
                ft = int(sum(int(np.sum(i)) for i, _ in recs))
                f = int(sum(len(x["false"]) for _, x in recs))
                tot = [x for i, x in recs if i[s]]
                row[m] = {"false": f, "false_total": ft, "correct": int(sum(x["detected"]
                                                                          for x in tot)),
                          "total": len(tot),
                          "ttd_s": _pct([x["ttd_s"] for x in tot if x["detected"]]),
                          "ttd_eval_s": _pct([x["ttd_eval_s"] for x in tot if x["detected"]]),
                          "css1_max_avg": _pct([x["css1_max_avg"] for x in tot]),
                          "nis_failed": [x["css1_max_avg"] for x in tot]}
                healthy += [h for _, x in recs for h in x["healthy_max_avg"]]
            row["nis_healthy"] = healthy
            row["healthy_max_avg"] = _pct(healthy)
            res[v][grid] = row
    return res


def fault_table_study(experiment="table5_1", n_runs=500, *, seed=0, workers=1,
                      grids=THESIS_GRIDS, modes=FAULT_MODES, variants=VARIANTS,
                      duration_s=None, progress=None, albedo_dir=None,
                      thesis_filter=None) -> dict:
    """Monte Carlo of table 5.1 (``experiment`` "table5_1") or 5.2 ("table5_2"):
    ``n_runs`` runs (thesis: 500), run i seeded ``(seed, i)``; ``workers`` local processes
    (one numba thread each, :func:`lightcurve.studies.runner.process_pool`); ``progress``: a
    callable called after each run; ``thesis_filter``: overrides of the thesis filter
    (:func:`thesis_filter_overrides`; an ablation, recorded in the output).  Returns the
    :func:`summarise` tables with the thesis's numbers, the set-up and the mean CPU time of
    one run (``cpu_s_per_run``, s: every variant, grid and mode of the run)."""
    from .okeefe2015 import FAULT, THESIS_RESULTS

    if experiment not in EXPERIMENTS:
        raise ValueError(f"unknown experiment {experiment!r}; allowed: {', '.join(EXPERIMENTS)}")
    tf = thesis_filter_overrides(thesis_filter)
    kw = dict(controlled=EXPERIMENTS[experiment], grids=tuple(grids), modes=tuple(modes),
              variants=tuple(variants), duration_s=duration_s, albedo_dir=albedo_dir,
              thesis_filter=tf)
    jobs = [(np.random.SeedSequence([int(seed), i]), kw) for i in range(int(n_runs))]
    from ..studies.runner import map_in_pool

    runs = map_in_pool(_worker, jobs, workers, progress)
    det_r, dark_r = robust_detectors()
    return {
        "experiment": experiment, "controlled": EXPERIMENTS[experiment], "runs": len(runs),
        "seed": int(seed), "grids": list(grids), "modes": list(modes),
        "variants": list(variants), "failed_sensor": int(FAULT["sensor"]) + 1,
        "thesis_filter": tf,
        "t_fail_s": float(FAULT["t_fail_s"]),
        "detectors": {
            "thesis": {g: {"window": d.window, "threshold": d.limit()}
                       for g, d in ((g, thesis_detector(g)) for g in grids)},
            "robust": {"window": det_r.window, "threshold": det_r.limit(),
                       "threshold_all_correlated": float(det_r.limit(1.0)),
                       "t_start_s": det_r.t_start_s, "dark_g_min": dark_r.limit(),
                       "dark_window": dark_r.window}},
        "thesis_results": THESIS_RESULTS[experiment],
        "tables": summarise(runs, grids=grids, modes=modes, variants=variants),
        "workers": int(workers),
        "cpu_s_per_run": float(np.mean([r["cpu_s"] for r in runs])) if runs else None,
    }


GRID_LABELS = {"1p25x1": "1°×1.25°", "5x5": "5°×5°", "10x10": "10°×10°"}


def plot_fault_nis(summary: dict, png) -> None:
    """Fig. 5.5's comparison as empirical distribution functions: for each variant and grid,
    the fraction of healthy sensors (over the run) and of failed CSS 1 (after the failure, per
    mode) whose largest averaged NIS is below x, log x, with the detection threshold — where
    the healthy curve crosses the threshold is the share *not* falsely flagged, where a
    failed curve crosses it the share missed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io.atomic import atomic_path

    variants = summary["variants"]
    grids = summary["grids"]
    fig, axes = plt.subplots(len(variants), len(grids), figsize=(4.2 * len(grids),
                                                                 3.2 * len(variants)),
                             squeeze=False, sharex=True, sharey=True)

    def ecdf(ax, v, **kw):
        x = np.sort(np.asarray([y for y in v if y is not None and np.isfinite(y)], float))
        if x.size:
            ax.step(np.clip(x, 1e-3, None), np.arange(1, x.size + 1) / x.size, where="post",
                    **kw)

    for i, v in enumerate(variants):
        for j, g in enumerate(grids):
            ax = axes[i][j]
            row = summary["tables"][v][g]
            ecdf(ax, row["nis_healthy"], color="0.3", lw=2,
                 label=f"healthy CSS 2-8 ({len(row['nis_healthy'])})")
            for m, c in zip(summary["modes"], ("C3", "C0", "C1")):
                ecdf(ax, row[m]["nis_failed"], color=c, label=f"CSS 1 {m}")
            thr = (summary["detectors"]["thesis"][g]["threshold"] if v == "thesis"
                   else summary["detectors"]["robust"]["threshold"])
            ax.axvline(thr, color="k", ls="--", lw=1, label=f"threshold {thr:.2f}")
            ax.set_xscale("log")
            ax.grid(alpha=0.3)
            ax.set_title(f"{v} variant, {GRID_LABELS.get(g, g)} grid", fontsize=9)
            if i == len(variants) - 1:
                ax.set_xlabel("largest averaged NIS")
            if j == 0:
                ax.set_ylabel("fraction below")
            ax.legend(fontsize=6, loc="lower right")
    fig.suptitle(f"{summary['experiment']}: largest averaged NIS, healthy sensors vs failed "
                 f"CSS 1 ({summary['runs']} runs)", fontsize=10)
    fig.tight_layout()
    try:
        with atomic_path(png) as tmp:
            fig.savefig(tmp, format="png", dpi=110)
    finally:
        plt.close(fig)
