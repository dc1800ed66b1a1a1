"""Handlers of the ``lightcurve css calibrate | faults | vmm | sun-models`` subcommands (thin
wrappers over :mod:`.calibration`, :mod:`.fault`, :mod:`.vmm`, :mod:`.sun_models`)."""

from __future__ import annotations

import json

import numpy as np

__all__ = ["cmd_calibrate", "cmd_faults", "cmd_vmm", "cmd_sun_models"]


def _albedo(spec):
    from .albedo import load_albedo_map

    if spec in (None, "builtin"):
        return "builtin"
    if spec == "none":
        return False
    return load_albedo_map(spec)


def _write_json(path, obj):
    from ..io.atomic import atomic_write_text

    atomic_write_text(path, json.dumps(obj, indent=1, default=float) + "\n")
    print(f"wrote {path}")


def cmd_calibrate(args) -> int:
    """Simulate one §4.4 case and run the full and reduced calibration filters."""
    from .calibration import (CalibrationParams, acceptance_summary, run_calibration,
                              simulate_calibration_case)

    truth = _albedo(args.albedo_truth)
    filt = _albedo(args.albedo_filter) if args.albedo_filter else truth
    case = simulate_calibration_case(args.seed, duration_s=args.duration_s, dt_s=args.dt_s,
                                     albedo_truth=truth, scale_sigma=args.scale_sigma,
                                     misalignment_sigma_deg=args.misalignment_sigma_deg,
                                     star_period_s=args.star_period_s)
    report = {}
    for name, prm in (("full", CalibrationParams()), ("reduced", CalibrationParams.reduced())):
        if args.filter not in ("both", name):
            continue
        res = run_calibration(case.css_nominal, case.t, case.Y, case.gyro, case.sun_N,
                              case.lit, case.r_I_m, case.epoch_utc,
                              params=prm.for_gyro(case.info["spec"]),
                              albedo=filt if filt is not False else "builtin",
                              q_star=case.q_star, star_valid=case.star_valid)
        s = acceptance_summary(case, res)
        print(f"{name} filter ({case.t.size} samples, {case.t[-1]:.0f} s):")
        print("  sensor saw_sun  scale_err  3sigma   d_az_err  d_el_err  3sig_az  3sig_el (deg)")
        for k in range(s["n_sensors"]):
            print(f"  {k + 1:5d}  {str(bool(s['saw_sun'][k])):6s}  {s['scale_err'][k]:+8.4f}  "
                  f"{s['scale_3sigma'][k]:7.4f}  {s['mis_err_deg'][k, 0]:+8.3f}  "
                  f"{s['mis_err_deg'][k, 1]:+8.3f}  {s['mis_3sigma_deg'][k, 0]:7.3f}  "
                  f"{s['mis_3sigma_deg'][k, 1]:7.3f}")
        saw = s["saw_sun"]
        ok = bool(np.all(s["scale_3sigma"][saw] <= 0.05) and np.all(s["mis_3sigma_deg"][saw] <= 2))
        print(f"  acceptance (3sigma scale <= 0.05, misalignment <= 2 deg for sensors that saw "
              f"the Sun): {'met' if ok else 'not met'}")
        report[name] = {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                        for k, v in s.items() if k not in ("attitude_err_deg", "bias_err")}
        report[name]["acceptance_met"] = ok
    if args.output:
        _write_json(args.output, report)
    return 0


FAULTS_OURS_DEFAULTS = {"window": 50, "prob": 0.999999, "start_s": 600.0, "fail_s": 1950.0,
                        "no_dark": False, "star_period_s": 10.0}
"""Defaults of the ``css faults`` options that only our own experiment takes (the parser
leaves them None, so that an option given with the thesis's tables is caught)."""


def _fault_tables(args) -> int:
    """``css faults --experiment table5_1|table5_2``: O'Keefe's tables beside ours."""
    from ..cli._args import progress_bar
    from ..errors import InputError
    from .fault_tables import THESIS_GRIDS, fault_table_study, plot_fault_nis

    for k in FAULTS_OURS_DEFAULTS:
        if getattr(args, k, None) is not None:
            raise InputError("applies to --experiment ours only (the tables use the thesis's "
                             "detector and our default one)", field="--" + k.replace("_", "-"),
                             value=getattr(args, k))
    grids = tuple(g.strip() for g in args.grids.split(",") if g.strip())
    bad = [g for g in grids if g not in THESIS_GRIDS]
    if bad or not grids:
        raise InputError("unknown TOMS grid", field="--grids", value=args.grids,
                         allowed=", ".join(THESIS_GRIDS))
    variants = ("thesis", "robust") if args.variant is None else (args.variant,)
    tf = {}
    for item in args.thesis_filter or []:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise InputError("expected NAME=VALUE", field="--thesis-filter", value=item)
        tf[name.strip()] = value.strip()
    from .fault_tables import thesis_filter_overrides

    tf = thesis_filter_overrides(tf)      # checked before any work
    runs = 500 if args.runs is None else args.runs
    with progress_bar(total=runs, desc=f"css faults {args.experiment}", quiet=args.quiet,
                      unit="run") as bar:
        out = fault_table_study(args.experiment, runs, seed=args.seed, workers=args.workers,
                                grids=grids, variants=variants, progress=bar.update,
                                thesis_filter=tf)
    th = out["thesis_results"]
    print(f"O'Keefe {args.experiment.replace('table', 'table ').replace('_', '.')} "
          f"({'controlled' if out['controlled'] else 'tumbling'}), CSS {out['failed_sensor']} "
          f"failing at {out['t_fail_s']:g} s, {out['runs']} runs (thesis: 500)"
          + ("; thesis filter changed: " + ", ".join(f"{k} = {v}" for k, v in
                                                     out["thesis_filter"].items())
             if out["thesis_filter"] else ""))
    print("false detections / initialised sensors; correct detections / runs with CSS 1 "
          "initialised; median time to detection from the failure (s)")
    head = f"{'grid':7s} {'mode':7s} {'thesis':>24s}"
    for v in variants:
        head += f" | {v + ' variant':>34s}"
    print(head)
    for g in grids:
        for m in out["modes"]:
            t = th.get(g, {}).get(m)
            line = f"{g:7s} {m:7s} "
            line += (f"{t[0]:4d}/{t[1]:<5d} {t[2]:4d}/{t[3]:<4d} ({100 * t[2] / t[3]:5.1f}%)"
                     if t else f"{'-':>24s}")
            for v in variants:
                r = out["tables"][v][g][m]
                pc = 100.0 * r["correct"] / r["total"] if r["total"] else float("nan")
                ttd = r["ttd_s"]["p50"] if r["ttd_s"] else float("nan")
                line += (f" | {r['false']:4d}/{r['false_total']:<5d} {r['correct']:4d}/"
                         f"{r['total']:<4d} ({pc:5.1f}%) {ttd:6.0f}")
            print(line)
    if args.output:
        _write_json(args.output, out)
    if args.plot:
        from pathlib import Path

        png = Path(args.output).with_suffix(".png") if args.output else Path("css-faults.png")
        plot_fault_nis(out, png)
        print(f"wrote {png}")
    return 0


def cmd_faults(args) -> int:
    """Fault-detection Monte Carlo (tables 5.1-5.2)."""
    if getattr(args, "experiment", "ours") != "ours":
        return _fault_tables(args)
    if getattr(args, "plot", False):
        from ..errors import InputError

        raise InputError("applies to --experiment table5_1 / table5_2 only", field="--plot",
                         value=True)
    if getattr(args, "thesis_filter", None):
        from ..errors import InputError

        raise InputError("applies to --experiment table5_1 / table5_2 only",
                         field="--thesis-filter", value=args.thesis_filter[0])
    if getattr(args, "variant", None) is not None:
        from ..errors import InputError

        raise InputError("applies to --experiment table5_1 / table5_2 only",
                         field="--variant", value=args.variant)
    args.runs = 300 if args.runs is None else args.runs
    for k, v in FAULTS_OURS_DEFAULTS.items():
        if getattr(args, k, None) is None:
            setattr(args, k, v)
    from .fault import AveragedNISDetector, DarkSensorDetector, fault_study

    det = AveragedNISDetector(window=args.window, prob=args.prob, t_start_s=args.start_s)
    dark = None if args.no_dark else DarkSensorDetector(t_start_s=args.start_s)
    from ..cli._args import progress_bar

    with progress_bar(total=4 * args.runs, desc="css faults", quiet=args.quiet,
                      unit="run") as bar:
        out = fault_study(args.runs, seed=args.seed, workers=args.workers, detector=det,
                          dark=dark, t_fail_s=args.fail_s,
                          star_period_s=args.star_period_s,
                          progress=bar.update)
    d = out["detector"]
    print(f"averaged-NIS detector: window {d['window']}, threshold {d['threshold']:.3f} "
          f"(two-sided chi2 interval, prob {d['prob']}), decisions after {d['t_start_s']:g} s")
    if out["dark_detector"] is not None:
        dd = out["dark_detector"]
        print(f"dark-sensor test: window {dd['window']}, u >= {dd['u_min']:g}, flag when "
              f"gain + {dd['z']:g} sigma < {dd['g_min']:.3f}")
    print("mode     runs  detected  detected(observable)  (exposed+calibrated)  false_alarm  "
          "wrong_sensor  ttd_median_s  ttd_p90_s")
    for m, v in out["modes"].items():
        f = (lambda x, fmt: "-" if x is None else format(x, fmt))
        print(f"{m:8s} {v['runs']:4d}  {f(v.get('detection_rate'), '8.3f')}  "
              f"{f(v.get('detection_rate_observable'), '20.3f')}  "
              f"{f(v.get('detection_rate_exposed_calibrated'), '20.3f')}  "
              f"{v['false_alarm_rate']:11.4f}  "
              f"{f(v.get('wrong_sensor_rate'), '12.3f')}  {f(v.get('ttd_median_s'), '12.0f')}  "
              f"{f(v.get('ttd_p90_s'), '9.0f')}")
    if args.output:
        _write_json(args.output, out)
    return 0


def cmd_vmm(args) -> int:
    """VMM vs SMM Monte Carlo with a plot."""
    from .vmm import plot_vmm_study, vmm_study

    from ..cli._args import progress_bar

    with progress_bar(total=args.runs, desc="css vmm", quiet=args.quiet, unit="run") as bar:
        r = vmm_study(args.runs, seed=args.seed, duration_s=args.duration_s,
                      fov_half_angle_deg=args.fov_deg, albedo=args.albedo, progress=bar.update)
    print(f"{r['runs']} runs; median / RMS attitude error (deg) by number of lit photodiodes:")
    for k, v in list(r["by_n_lit"].items()) + [("1-2", r["lt3"])]:
        if v["samples"]:
            print(f"  {k:>3s}: {v['samples']:7d} samples  SMM {v['smm_median_deg']:.3f} / "
                  f"{v['smm_rms_deg']:.3f}   VMM {v['vmm_median_deg']:.3f} / {v['vmm_rms_deg']:.3f}")
    if args.plot:
        from pathlib import Path

        png = Path(args.output).with_suffix(".png") if args.output else Path("css-vmm.png")
        plot_vmm_study(r, png)
        print(f"wrote {png}")
    if args.output:
        out = {k: v for k, v in r.items() if k != "example"}
        out.update(kind="css vmm", seed=args.seed, duration_s=args.duration_s,
                   fov_half_angle_deg=args.fov_deg, albedo=bool(args.albedo))
        _write_json(args.output, out)
    return 0


def cmd_sun_models(args) -> int:
    """Table 4.5: almanac (Vallado eq. 4.39) vs DE421 Sun directions; ``--table``: the whole
    table measured (:func:`.sun_models.sun_model_table`) beside the thesis's numbers."""
    from .sun_models import THESIS_ROW, THESIS_TABLE_4_5, compare_models, sun_model_table

    if args.table:
        tab = sun_model_table()
        print(f"Sun direction vs DE421, {tab['days']:g} days from {tab['start_utc']} every "
              f"{tab['step_h']:g} h (thesis: O'Keefe table 4.5, vs SPICE)")
        print(f"{'model':18s} {'time':>6s} {'mean deg':>10s} {'max deg':>10s}   thesis row: "
              "time, mean, max")
        for r in tab["rows"]:
            th = THESIS_ROW.get(r["model"])
            tt = THESIS_TABLE_4_5.get(th) if th else None
            f = (lambda v: "–" if v is None else f"{v:.2g}")
            print(f"{r['model']:18s} {r['time_rel']:6.1f} {f(r['mean_deg']):>10s} "
                  f"{f(r['max_deg']):>10s}   {th or '–'}: "
                  + (", ".join(f(v) for v in tt) if tt else "–"))
        if args.output:
            _write_json(args.output, tab)
        return 0
    if args.output:
        from ..errors import InputError

        raise InputError("-o/--output needs --table (the per-date comparison prints only)",
                         field="--output", value=str(args.output), allowed="with --table")
    rows = compare_models(args.dates)
    print("date (UTC)                 almanac-as-GCRS vs DE421 (deg)   "
          "almanac vs DE421 mean-of-date (deg)   range diff (km)")
    for r in rows:
        print(f"{r['date_utc']:26s} {r['vs_gcrs_deg']:12.4f} {r['vs_mean_of_date_deg']:36.4f} "
              f"{r['range_diff_km']:18.0f}")
    return 0
