"""``lightcurve css``: coarse-sun-sensor simulation, estimation and studies (O'Keefe 2015)."""

from __future__ import annotations

import numpy as np

from ._args import SEED, number, output_not_input

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

    from ..css.recording import write_recording
    from ..css.study import gyroless_params, settled_mask
    from ..css.sunline_ekf import FilterParams
    from ..css.truth import Scenario, simulate

    output_not_input(args.out, args.config, args.albedo, args.filter_albedo, option="--out")
    css = _css_sensors(args.config, args.fov_deg)
    gyro = None if args.gyro == "none" else args.gyro
    fp = FilterParams() if gyro else gyroless_params()
    from dataclasses import replace as _replace

    fp = _replace(fp, albedo_model=args.filter_albedo != "none")
    sc = Scenario(css, estimator=args.estimator, gyro=gyro, controlled=args.controlled,
                  duration_s=args.duration_s, dt_s=args.dt_s, epoch_utc=args.epoch,
                  albedo=_css_albedo(args.albedo), filter_params=fp,
                  filter_albedo=_css_albedo(args.filter_albedo) if args.filter_albedo != "none" else None)
    r = simulate(sc, args.seed)
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
    if args.out:
        write_recording(args.out, r, css, args.epoch, gyro is not None)
        print(f"wrote {args.out}")
    return 0


def _cmd_css_estimate(args) -> int:

    from ..css.recording import read_recording
    from ..css.single_point import angle_deg, estimate
    from ..css.study import gyroless_params
    from ..css.sunline_ekf import FilterParams, run_filter

    output_not_input(args.out, args.recording, option="--out")
    rec = read_recording(args.recording)
    gyro = None if args.no_gyro else rec["gyro"]
    if args.estimator in ("ekf", "eckf"):
        fp = FilterParams() if gyro is not None else gyroless_params()
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
    if args.out:
        from ..io.atomic import atomic_path

        with atomic_path(args.out, suffix=".csv") as tmp:
            np.savetxt(tmp, np.column_stack([rec["t"], s_hat]), delimiter=",",
                       header="t_s,s_hat_x,s_hat_y,s_hat_z (body axes)", comments="")
        print(f"wrote {args.out}")
    return 0


def _cmd_css_study(args) -> int:
    from dataclasses import replace

    from ..css.study import load_study, run_study, write_report

    spec = load_study(args.pipeline)
    if args.runs is not None:
        spec = replace(spec, n_runs=args.runs)
    cases = run_study(spec)
    if args.out:
        out_dir = args.out
    else:  # derived from the study's name (data): keep it inside the current folder
        from ..io.paths import safe_output_path

        out_dir = safe_output_path(".", f"{spec.name}-report", field="study.name")
    out = write_report(spec, cases, out_dir)
    print((out / "summary.txt").read_text(), end="")
    print(f"report in {out}/ (summary.json, summary.txt, envelopes.png, error_maps.png)")
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "css", help="coarse sun sensors: simulate, estimate the Sun direction, Monte Carlo studies",
        description="Coarse-sun-sensor (CSS) tools after O'Keefe (2015): cosine sensors with "
        "Earth albedo, rate gyros, single-point (WAVG/LSMN/WLSMN) and sequential (EKF/ECKF) "
        "sun-direction estimators and MRP sun-pointing control.")
    css_sub = p.add_subparsers(title="css commands", metavar="CSS_COMMAND")

    def common(q):
        q.add_argument("--config", default="dual_pyramid",
                       help="sensor set: dual_pyramid, cube or a sensor TOML file (default dual_pyramid)")
        q.add_argument("--fov-deg", type=number(0.0, 90.0, lo_open=True), default=70.0,
                       help="FOV half angle of the bundled sets, deg (default 70)")

    s = css_sub.add_parser(
        "simulate", help="simulate one dispersed run (truth, CSS, gyro, estimator, control)",
        description="Simulate one §2.4 run: 400 km polar orbit, dispersed attitude, rates and "
        "sensor errors, CSS outputs with albedo, gyro, the chosen estimator and optionally the "
        "MRP sun-pointing controller. Prints the angular error and optionally writes an HDF5 "
        "recording for 'css estimate'.")
    common(s)
    s.add_argument("--estimator", default="ekf", choices=("ekf", "eckf", "wavg", "lsmn", "wlsmn"),
                   help="estimator in the loop (default ekf)")
    s.add_argument("--gyro", default="tactical", choices=("rate", "tactical", "navigation", "none"),
                   help="gyro grade, or none for gyro-less operation (default tactical)")
    s.add_argument("--controlled", action="store_true", help="run the sun-pointing controller")
    s.add_argument("--duration-s", type=number(0.0, 366 * 86400.0, lo_open=True), default=1800.0, help="duration, s (default 1800)")
    s.add_argument("--dt-s", type=number(1e-3, 60.0), default=0.5, help="sample and control step, s (default 0.5)")
    s.add_argument("--epoch", default="2015-03-01T00:00:00Z", help="epoch, ISO 8601 UTC")
    s.add_argument("--albedo", default="builtin",
                   help="builtin (zonal CERES fit), none, or a CERES CSV / TOMS .dat file")
    s.add_argument("--filter-albedo", default="builtin",
                   help="albedo model inside the EKF/ECKF: builtin (default), none (no albedo "
                   "model, first-session filter), or a CERES CSV / TOMS .dat file")
    s.add_argument("--seed", type=SEED, default=1, help="random seed (default 1)")
    s.add_argument("--settle-s", type=number(0.0), default=300.0,
                   help="ignore errors this long after entering sunlight, s (default 300)")
    s.add_argument("--out", help="write the run to this HDF5 file")
    s.set_defaults(func=_cmd_css_simulate)

    e = css_sub.add_parser(
        "estimate", help="run an estimator on a CSS recording",
        description="Run WAVG, LSMN, WLSMN, the sun-line EKF or the ECKF on a CSS recording "
        "(HDF5 written by 'css simulate'); prints the error against the truth when present.")
    e.add_argument("recording", help="HDF5 CSS recording")
    e.add_argument("--estimator", default="ekf", choices=("ekf", "eckf", "wavg", "lsmn", "wlsmn"))
    e.add_argument("--no-gyro", action="store_true",
                   help="ignore the gyro: rates from successive estimates (eq. 3.67)")
    e.add_argument("--threshold", type=number(), default=0.5,
                   help="activity threshold of the single-point methods (default 0.5)")
    e.add_argument("--settle-s", type=number(0.0), default=300.0, help="skip this long before scoring, s")
    e.add_argument("--out", help="write the estimates to this CSV file")
    e.set_defaults(func=_cmd_css_estimate)

    st = css_sub.add_parser(
        "study", help="Monte Carlo study from a pipeline TOML (percentile envelopes, time above 15/30 deg)",
        description="Run a CSS Monte Carlo study (e.g. pipelines/css/*.toml) and write "
        "summary.json, summary.txt, envelopes.png and error_maps.png: 99th-percentile errors "
        "after the first minutes in sunlight next to the thesis values, time above 15/30 deg "
        "per orbit, with control the time to sun pointing, and the noise-free single-point "
        "error maps (figs. 3.1-3.2).")
    st.add_argument("pipeline", help="study TOML file")
    st.add_argument("--runs", type=number(1, 100000, integer=True), help="override the number of runs")
    st.add_argument("--out", help="report folder (default <study name>-report)")
    st.set_defaults(func=_cmd_css_study)

    # --- calibration, fault detection, VMM/SMM, Sun models (handlers in
    # lightcurve/css/cli_tools.py) ---
    def _lazy(name):
        def run(args):
            from ..css import cli_tools

            return getattr(cli_tools, name)(args)
        return run

    ca = css_sub.add_parser(
        "calibrate", help="on-orbit CSS calibration filters (full and reduced) on a simulated orbit",
        description="Simulate O'Keefe's §4.4 case (one orbit, tumbling, dual pyramid, scale "
        "factors dispersed 30 %%, misalignments, albedo, gyro, star tracker) and run the full "
        "calibration ECKF (MRP, gyro bias, scale factors, misalignments, albedo model) and the "
        "reduced filter (albedo as a considered bias). Prints per-sensor errors and 3-sigma bounds.")
    ca.add_argument("--filter", choices=("full", "reduced", "both"), default="both")
    ca.add_argument("--seed", type=SEED, default=0, help="random seed (default 0)")
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
    ca.add_argument("--out", help="write the summary to this JSON file")
    ca.set_defaults(func=_lazy("cmd_calibrate"))

    fa = css_sub.add_parser(
        "faults", help="fault detection by averaged per-sensor NIS (off / stuck / random failures)",
        description="Monte Carlo of O'Keefe §5.1: one sensor fails (off, stuck or random) at "
        "--fail-s; the averaged per-sensor NIS of the calibration filter is tested against "
        "the chi-square bound, and a dark-sensor test flags a lit sensor whose gain is "
        "confidently below the prior's smallest plausible value. Reports detection and false-alarm rates and times to detection.")
    fa.add_argument("--runs", type=number(1, 100000, integer=True), default=300,
                    help="runs per failure mode (default 300)")
    fa.add_argument("--workers", type=number(1, 256, integer=True), default=1)
    fa.add_argument("--seed", type=SEED, default=0)
    fa.add_argument("--window", type=number(1, 100000, integer=True), default=50,
                    help="averaging window, valid samples (default 50)")
    fa.add_argument("--prob", type=number(0.0, 1.0, lo_open=True, hi_open=True), default=0.999999,
                    help="probability of the chi-square interval (default 1-1e-6)")
    fa.add_argument("--start-s", type=number(0.0), default=600.0,
                    help="no decision before this time, s (default 600)")
    fa.add_argument("--fail-s", type=number(0.0), default=1950.0, help="failure time, s (default 1950)")
    fa.add_argument("--no-dark", action="store_true",
                    help="averaged NIS only: switch off the dark-sensor test (a lit sensor whose "
                    "output stays at zero; catches off failures of never-calibrated sensors)")
    fa.add_argument("--star-period-s", type=number(0.0, 3600.0), default=10.0,
                    help="star-tracker period, s; 0 for none (default 10)")
    fa.add_argument("--out", help="write the summary to this JSON file")
    fa.set_defaults(func=_lazy("cmd_faults"))

    vm = css_sub.add_parser(
        "vmm", help="voltage vs sun-vector measurement model in a full-attitude MEKF",
        description="DiGregorio's comparison: MEKF with magnetometer, gyro and photodiodes, "
        "photodiodes used as a least-squares Sun vector (SMM) or as individual voltages (VMM); "
        "attitude errors grouped by the number of lit photodiodes, with a plot.")
    vm.add_argument("--runs", type=number(1, 100000, integer=True), default=20)
    vm.add_argument("--seed", type=SEED, default=0)
    vm.add_argument("--duration-s", type=number(10.0, 86400.0), default=3000.0)
    vm.add_argument("--fov-deg", type=number(0.0, 90.0, lo_open=True), default=70.0,
                    help="photodiode FOV half angle, deg (cube; default 70)")
    vm.add_argument("--albedo", action="store_true", help="Earth albedo in the truth (unmodelled)")
    vm.add_argument("--plot", help="write the figure to this PNG file")
    vm.add_argument("--out", help="write the summary to this JSON file")
    vm.set_defaults(func=_lazy("cmd_vmm"))

    sm = css_sub.add_parser(
        "sun-models", help="almanac (Vallado) vs DE421 Sun direction (table 4.5)",
        description="Angular difference between the low-precision almanac Sun formula "
        "(O'Keefe eq. 4.39) and skyfield/DE421 at the given dates.")
    sm.add_argument("dates", nargs="*", default=["2005-01-01T00:00:00Z", "2010-01-01T00:00:00Z",
                                                 "2015-03-01T00:00:00Z", "2020-01-01T00:00:00Z",
                                                 "2025-01-01T00:00:00Z"],
                    help="ISO 8601 UTC dates")
    sm.set_defaults(func=_lazy("cmd_sun_models"))
