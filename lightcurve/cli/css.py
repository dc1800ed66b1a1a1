"""``lightcurve css``: coarse-sun-sensor simulation, estimation and studies (O'Keefe 2015)."""

from __future__ import annotations

import argparse

import numpy as np

from ._args import (add_command, add_executors, add_group, add_output, add_plot, add_quiet,
                    add_seed, add_workers, number, output_not_input, output_path, report_written)

__all__ = ["register"]


def _css_sensors(name, fov_deg):
    from ..css.configurations import configuration_by_name

    if name in ("dual_pyramid", "cube"):
        return configuration_by_name(name, fov_half_angle_deg=fov_deg)
    return configuration_by_name(name)


def _css_albedo(spec):
    from ..css.albedo import load_albedo_map

    if spec == "builtin":
        return None
    if spec == "none":
        return False
    return load_albedo_map(spec)


def _cmd_css_simulate(args) -> int:

    """Simulate one §2.4 run: 400 km polar orbit, dispersed attitude, rates and sensor errors, CSS
    outputs with albedo, gyro, the chosen estimator and optionally the MRP sun-pointing
    controller. Prints the angular error and optionally writes an HDF5 recording for 'css
    estimate'.
    """
    from ..css.recording import write_css_recording
    from ..css.study import settled_mask
    from ..css.sunline_ekf import default_filter_params
    from ..css.truth import CSSScenario, simulate_css

    output_not_input(args.output, args.config, args.albedo, args.filter_albedo, option="--output")
    css = _css_sensors(args.config, args.fov_deg)
    from ..memory import check_allocation

    # the simulation's per-step arrays (measured 590 B per step with 8 sensors), refused
    # before anything is allocated
    n_steps = int(args.duration_s / args.dt_s) + 1
    check_allocation(n_steps * (400 + 32 * len(np.atleast_2d(css.normals))),
                     f"CSS simulation of {n_steps} steps", field="--duration-s/--dt-s",
                     value=n_steps)
    gyro = None if args.gyro == "none" else args.gyro
    fp = default_filter_params(gyro)
    from dataclasses import replace as _replace

    fp = _replace(fp, albedo_model=args.filter_albedo != "none")
    if args.variant is not None:
        # O'Keefe (2015) §2.4 set-up (60° FOV, structure horizon, 2 Hz / 10 Hz, J2-J6 orbit,
        # TOMS albedo when the data folder is there) with the thesis or robust estimators
        from ..css.experiments import thesis_scenario

        if args.config not in ("dual_pyramid", "cube"):
            from ..errors import InputError

            raise InputError("--variant runs the thesis set-up: dual_pyramid or cube only",
                             field="--config", value=args.config, allowed="dual_pyramid, cube")
        sc = thesis_scenario(args.config, args.estimator, variant=args.variant, gyro=gyro,
                             controlled=args.controlled, duration_s=args.duration_s,
                             albedo="toms" if args.albedo == "builtin" else _css_albedo(args.albedo))
        css = sc.css
    else:
        sc = CSSScenario(css, estimator=args.estimator, gyro=gyro, controlled=args.controlled,
                         duration_s=args.duration_s, dt_s=args.dt_s, epoch_utc=args.epoch,
                         albedo=_css_albedo(args.albedo), filter_params=fp,
                         filter_albedo=(_css_albedo(args.filter_albedo)
                                        if args.filter_albedo != "none" else None))
    r = simulate_css(sc, args.seed)
    m = settled_mask(r.t, r.lit, args.settle_s)
    e = r.error_deg[m]
    print(f"{css.name}: {r.t.size} samples, sunlit {np.mean(r.lit > 0.999) * 100:.0f} %, "
          f"estimator {args.estimator}, gyro {args.gyro}, "
          f"{'controlled' if args.controlled else 'tumbling'}")
    if e.size:
        print(f"angular error after {args.settle_s:g} s in sunlight: median {np.median(e):.2f} deg, "
              f"99th percentile {np.percentile(e, 99):.2f} deg")
    if args.controlled:
        pe = np.degrees(np.arccos(np.clip(r.s_true @ r.info["pointing_axis"], -1, 1)))
        print(f"final pointing error {pe[-1]:.2f} deg")
    if args.output:
        write_css_recording(args.output, r, css, args.epoch, gyro is not None)
        report_written(args.output)
    return 0


def _cmd_css_estimate(args) -> int:

    """Run WAVG, LSMN, WLSMN, the sun-line EKF or the ECKF on a CSS recording (HDF5 written by 'css
    simulate'); prints the error against the truth when present.
    """
    from ..css.recording import read_css_recording
    from ..css.single_point import angle_deg, estimate
    from ..css.sunline_ekf import default_filter_params, run_filter

    output_not_input(args.output, args.recording, option="--output")
    rec = read_css_recording(args.recording)
    gyro = None if args.no_gyro else rec["gyro"]
    if args.estimator in ("ekf", "eckf"):
        fp = default_filter_params(gyro)
        fp = fp.__class__(**{**fp.__dict__, "fov_half_angle_deg": float(np.degrees(np.max(rec["fov_half_angle_rad"])))})
        s_hat = run_filter(args.estimator, rec["t"], rec["y"], rec["normals"], gyro=gyro,
                           params=fp)["s_hat"]
    else:
        s_hat = estimate(args.estimator, rec["y"], rec["normals"], args.threshold)
    print(f"{args.recording}: {rec['t'].size} samples, estimator {args.estimator}, "
          f"gyro {'yes' if gyro is not None else 'no'}")
    if rec["truth"] is not None and "s_body" in rec["truth"]:
        err = angle_deg(s_hat, rec["truth"]["s_body"])
        lit = rec["truth"].get("lit", np.ones(err.size)) > 0.999
        sel = lit & (rec["t"] >= rec["t"][0] + args.settle_s)
        if sel.any():
            print(f"angular error (sunlit, after {args.settle_s:g} s): median "
                  f"{np.median(err[sel]):.2f} deg, 99th percentile {np.percentile(err[sel], 99):.2f} deg")
    if args.output:
        from ..io.atomic import atomic_path

        with atomic_path(args.output, suffix=".csv") as tmp:
            np.savetxt(tmp, np.column_stack([rec["t"], s_hat]), delimiter=",",
                       header="t_s,s_hat_x,s_hat_y,s_hat_z (body axes)", comments="")
        report_written(args.output)
    return 0


def _cmd_css_study(args) -> int:
    """Run or resume a CSS Monte Carlo study (pipelines/css/okeefe2015/*.toml: the thesis's
    experiments, thesis and robust variants side by side) and write summary.json and a
    self-contained report.html: the 99th-percentile error level next to the thesis's number,
    percentile envelopes against sunlit time, time above 15/30 deg per orbit. Finished runs are
    kept under DIR/runs and skipped on restart.
    """
    from ..css.study import load_css_study, run_css_study

    spec = load_css_study(args.pipeline)
    out_dir = args.output
    if out_dir is None:  # derived from the study's name (data): keep it inside the current folder
        from ..io.paths import safe_output_path

        out_dir = safe_output_path(".", f"{spec.name}-report", field="study.name")
    summary = run_css_study(spec, out_dir, runs=args.runs, workers=args.workers,
                        scheduler=args.scheduler, dask_local=args.dask_local, force=args.force,
                        progress=not args.quiet)
    print(f"{spec.name}: {summary['verdict']['text']}")
    print(f"{'estimator':>9} {'variant':>7} {'gyro':>12} {'runs':>5} {'p99 lvl':>8} "
          f"{'thesis':>7} {'>15 max min/orb':>15}")
    for c in summary["cases"]:
        lv = c.get("p99_level_deg")
        th = c.get("thesis_p99_deg")
        if th is not None:   # a bound printed as one (okeefe2015.thesis_p99_bound)
            th = {"lower": ">", "upper": "<="}.get(c.get("thesis_p99_bound"), "") + format(th, "g")
        a15 = c.get("above15_s_per_orbit", {}).get("max")
        print(f"{c['estimator']:>9} {c['variant']:>7} {c['gyro']:>12} {c['runs']:5d} "
              f"{'-' if lv is None else format(lv, '8.2f'):>8} {'-' if th is None else th:>7} "
              f"{'-' if a15 is None else format(a15 / 60, '15.2f'):>15}")
    print(f"report in {out_dir}/ (summary.json, report.html)")
    return 0


def _output(q, text) -> None:
    """``-o/--output FILE`` plus the deprecated hidden alias ``--out``."""
    add_output(q, what="file", help=text)
    q.add_argument("--out", dest="output", type=output_path("file"),
                   help=argparse.SUPPRESS)  # deprecated alias


def register(sub) -> None:
    _, css_sub = add_group(
        sub, "css", title="css commands", metavar="CSS_COMMAND",
        help="coarse sun sensors: simulate, estimate the Sun direction, Monte Carlo studies",
        description="Coarse-sun-sensor (CSS) tools after O'Keefe (2015): cosine sensors with "
        "Earth albedo, rate gyros, single-point (WAVG/LSMN/WLSMN) and sequential (EKF/ECKF) "
        "sun-direction estimators and MRP sun-pointing control.")

    def common(q):
        q.add_argument("--config", default="dual_pyramid",
                       help="sensor set: dual_pyramid, cube or a sensor TOML file (default dual_pyramid)")
        q.add_argument("--fov-deg", type=number(0.0, 90.0, lo_open=True), default=60.0,
                       help="FOV half angle of the bundled sets, deg (default 60, O'Keefe §2.1.3)")

    s = add_command(
        css_sub, "simulate", _cmd_css_simulate,
        help="simulate one dispersed run (truth, CSS, gyro, estimator, control)")
    common(s)
    s.add_argument("--estimator", default="ekf", choices=("ekf", "eckf", "wavg", "lsmn", "wlsmn"),
                   help="estimator in the loop (default ekf)")
    s.add_argument("--gyro", default="tactical", choices=("inertial", "intermediate", "moderate", "low", "rate", "tactical",
                            "navigation", "none"),
                   help="gyro grade (Table 2.3: inertial, intermediate, moderate, low; generic: "
                   "rate, tactical, navigation), or none for gyro-less operation (default tactical)")
    s.add_argument("--controlled", action="store_true", help="run the sun-pointing controller")
    s.add_argument("--variant", choices=("thesis", "robust"), default=None,
                   help="simulate O'Keefe's own set-up (§2.4: 60° FOV, structure horizon, 2 Hz CSS, "
                   "10 Hz gyro, J2-J6 orbit, TOMS albedo) with the thesis's estimators and "
                   "controller (thesis) or ours (robust); default: the generic set-up below")
    s.add_argument("--duration-s", type=number(0.0, 366 * 86400.0, lo_open=True), default=1800.0, help="duration, s (default 1800)")
    s.add_argument("--dt-s", type=number(1e-3, 60.0), default=0.5, help="sample and control step, s (default 0.5)")
    s.add_argument("--epoch", default="2015-03-01T00:00:00Z", help="epoch, ISO 8601 UTC")
    s.add_argument("--albedo", default="builtin",
                   help="builtin (zonal CERES fit), none, or a CERES CSV / TOMS .dat file")
    s.add_argument("--filter-albedo", default="builtin",
                   help="albedo model inside the EKF/ECKF: builtin (default), none (no albedo "
                   "model), or a CERES CSV / TOMS .dat file")
    add_seed(s, default=1)
    s.add_argument("--settle-s", type=number(0.0), default=300.0,
                   help="ignore errors this long after entering sunlight, s (default 300)")
    _output(s, "write the run to this HDF5 file (a CSS recording: 'css estimate', 'diagnose', 'plot')")

    e = add_command(
        css_sub, "estimate", _cmd_css_estimate, help="run an estimator on a CSS recording")
    e.add_argument("recording", help="HDF5 CSS recording")
    e.add_argument("--estimator", default="ekf", choices=("ekf", "eckf", "wavg", "lsmn", "wlsmn"),
                   help="sun-direction estimator: sun-line EKF or ECKF, or the single-point "
                   "WAVG, LSMN, WLSMN (default ekf)")
    e.add_argument("--no-gyro", action="store_true",
                   help="ignore the gyro: rates from successive estimates (eq. 3.67)")
    e.add_argument("--threshold", type=number(), default=0.5,
                   help="activity threshold of the single-point methods (default 0.5)")
    e.add_argument("--settle-s", type=number(0.0), default=300.0, help="skip this long before scoring, s")
    _output(e, "write the estimates to this CSV file (t_s,s_hat_x,s_hat_y,s_hat_z)")

    st = add_command(
        css_sub, "study", _cmd_css_study,
        help="Monte Carlo study (O'Keefe ch. 3 experiments): envelopes, p99, time above 15/30 deg")
    st.add_argument("pipeline", help="study TOML file")
    st.add_argument("--runs", type=number(1, 100000, integer=True), help="override the number of runs")
    add_output(st, what="folder", help="output folder; finished runs are kept there and "
               "skipped on restart (default <study name>-report)")
    st.add_argument("--out", dest="output", type=output_path("folder"),
                    help=argparse.SUPPRESS)  # deprecated alias
    add_executors(st)
    st.add_argument("--force", action="store_true",
                    help="discard stored runs of a different study in the output folder")
    add_quiet(st)

    # --- calibration, fault detection, VMM/SMM, Sun models (handlers in
    # lightcurve/css/cli_tools.py) ---
    def _lazy(name):
        def run(args):
            from ..css import cli_tools

            return getattr(cli_tools, name)(args)
        return run

    ca = add_command(
        css_sub, "calibrate", _lazy("cmd_calibrate"),
        help="on-orbit CSS calibration filters (full and reduced) on a simulated orbit",
        description="Simulate O'Keefe's §4.4 case (one orbit, tumbling, dual pyramid, scale "
        "factors dispersed 30 %, misalignments, albedo, gyro, star tracker) and run the full "
        "calibration ECKF (MRP, gyro bias, scale factors, misalignments, albedo model) and the "
        "reduced filter (albedo as a considered bias). Prints per-sensor errors and 3-sigma bounds.")
    ca.add_argument("--filter", choices=("full", "reduced", "both"), default="both",
                    help="calibration filter: the full ECKF, the reduced one (albedo as a "
                    "considered bias) or both (default both)")
    add_seed(ca, default=0)
    ca.add_argument("--duration-s", type=number(10.0, 86400.0), default=None,
                    help="duration, s (default one 400 km orbit, 5553 s)")
    ca.add_argument("--dt-s", type=number(0.05, 10.0), default=1.0, help="step, s (default 1)")
    ca.add_argument("--scale-sigma", type=number(0.0, 1.0), default=0.3,
                    help="1-sigma dispersion of the scale factors (default 0.3)")
    ca.add_argument("--misalignment-sigma-deg", type=number(0.0, 20.0), default=2.0,
                    help="1-sigma misalignment per angle, deg (default 2)")
    ca.add_argument("--star-period-s", type=number(0.0, 3600.0), default=10.0,
                    help="star-tracker period, s; 0 for none (default 10)")
    ca.add_argument("--albedo-truth", default="builtin",
                    help="albedo of the truth: builtin, none, or a CERES CSV / TOMS .dat file")
    ca.add_argument("--albedo-filter", default=None,
                    help="albedo map of the full filter (default: the truth's map)")
    _output(ca, "write the summary to this JSON file")

    fa = add_command(
        css_sub, "faults", _lazy("cmd_faults"),
        help="fault detection by averaged per-sensor NIS (off / stuck / random failures)",
        description="Monte Carlo of O'Keefe §5.1: one sensor fails (off, stuck or random) at "
        "--fail-s; the averaged per-sensor NIS of the calibration filter is tested against "
        "the chi-square bound, and a dark-sensor test flags a lit sensor whose gain is "
        "confidently below the prior's smallest plausible value. Reports detection and false-alarm rates and times to detection. "
        "With --experiment table5_1 / table5_2: O'Keefe's own tables (§5.2, the §4.4.3 case, "
        "tumbling / Sun-pointing, CSS 1 failing at 1950 s, TOMS 1°×1.25°, 5°×5° and 10°×10° "
        "filters), the thesis variant (its filter, 100-sample averaged NIS, thresholds "
        "3.0/1.2/1.2) beside our robust filter and detectors on the same runs, and the "
        "thesis's numbers.")
    fa.add_argument("--experiment", choices=("ours", "table5_1", "table5_2"), default="ours",
                    help="ours: our §4.4-type set-up with a random failing sensor (default); "
                    "table5_1 / table5_2: O'Keefe's tables 5.1 (tumbling) / 5.2 (controlled)")
    fa.add_argument("--runs", type=number(1, 100000, integer=True), default=None,
                    help="runs per failure mode (default 300; the thesis's 500 with "
                    "--experiment table5_*)")
    fa.add_argument("--variant", choices=("thesis", "robust"), default=None,
                    help="with --experiment table5_*: the thesis's filter and detector, or "
                    "ours (default both, side by side)")
    fa.add_argument("--thesis-filter", action="append", default=[], metavar="NAME=VALUE",
                    help="with --experiment table5_*: change one setting of the thesis filter "
                    "(an ablation, recorded in the output; repeatable), e.g. "
                    "fov_edge_margin=0.05, skip_in_shadow=true or floor_rule=predicted")
    fa.add_argument("--grids", default="1p25x1,5x5,10x10",
                    help="with --experiment table5_*: comma-separated TOMS grids of the full "
                    "filter (default 1p25x1,5x5,10x10)")
    add_workers(fa, default=1, help="local worker processes (default 1)")
    add_seed(fa, default=0)
    fa.add_argument("--window", type=number(1, 100000, integer=True), default=None,
                    help="averaging window, valid samples (default 50)")
    fa.add_argument("--prob", type=number(0.0, 1.0, lo_open=True, hi_open=True), default=None,
                    help="probability of the chi-square interval (default 1-1e-6)")
    fa.add_argument("--start-s", type=number(0.0), default=None,
                    help="no decision before this time, s (default 600)")
    fa.add_argument("--fail-s", type=number(0.0), default=None, help="failure time, s (default 1950)")
    fa.add_argument("--no-dark", action="store_true", default=None,
                    help="averaged NIS only: switch off the dark-sensor test (a lit sensor whose "
                    "output stays at zero; catches off failures of never-calibrated sensors)")
    fa.add_argument("--star-period-s", type=number(0.0, 3600.0), default=None,
                    help="star-tracker period, s; 0 for none (default 10)")
    _output(fa, "write the summary to this JSON file")
    add_plot(fa, help="with --experiment table5_*: also write fig. 5.5's comparison (OUTPUT "
             "with the suffix .png; css-faults.png without -o)")
    add_quiet(fa, help="no progress bar")

    vm = add_command(
        css_sub, "vmm", _lazy("cmd_vmm"),
        help="voltage vs sun-vector measurement model in a full-attitude MEKF",
        description="DiGregorio's comparison: MEKF with magnetometer, gyro and photodiodes, "
        "photodiodes used as a least-squares Sun vector (SMM) or as individual voltages (VMM); "
        "attitude errors grouped by the number of lit photodiodes, with a plot.")
    vm.add_argument("--runs", type=number(1, 100000, integer=True), default=20,
                    help="Monte Carlo runs (default 20)")
    add_seed(vm, default=0)
    vm.add_argument("--duration-s", type=number(10.0, 86400.0), default=3000.0,
                    help="duration of each run, s (default 3000)")
    vm.add_argument("--fov-deg", type=number(0.0, 90.0, lo_open=True), default=70.0,
                    help="photodiode FOV half angle, deg (cube; default 70)")
    vm.add_argument("--albedo", action="store_true", help="Earth albedo in the truth (unmodelled)")
    add_plot(vm, help="also write the figure: OUTPUT with the suffix .png (css-vmm.png without -o)")
    _output(vm, "write the summary to this JSON file")
    add_quiet(vm, help="no progress bar")

    sm = add_command(
        css_sub, "sun-models", _lazy("cmd_sun_models"),
        help="almanac (Vallado), ERFA and DE421 Sun directions (table 4.5)",
        description="Angular difference between the low-precision almanac Sun formula "
        "(O'Keefe eq. 4.39) and skyfield/DE421 at the given dates; with --table the whole of "
        "O'Keefe's table 4.5 (models, 6 h clock error, relative cost) measured over a year.")
    sm.add_argument("dates", nargs="*", default=["2005-01-01T00:00:00Z", "2010-01-01T00:00:00Z",
                                                 "2015-03-01T00:00:00Z", "2020-01-01T00:00:00Z",
                                                 "2025-01-01T00:00:00Z"],
                    help="ISO 8601 UTC dates")
    sm.add_argument("--table", action="store_true",
                    help="measure O'Keefe table 4.5 instead: almanac (eq. 4.39) and ERFA epv00 "
                    "vs DE421 over one year from the §2.4 epoch, also with a 6 h clock error, "
                    "and the time per call, beside the thesis's numbers")
    _output(sm, "with --table: write the table to this JSON file "
            "(input of 'python -m lightcurve.studies.reproduction --css-sun-models')")
