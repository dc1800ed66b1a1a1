"""The ``lightcurve`` command line.

Each area registers its subcommands in one ``_register_<area>`` function below; handlers are
thin: they parse arguments, call the library and print. Exit codes: 0 success, 1 run-time
failure, 2 bad usage or bad input (one clear line; the traceback only with ``--debug``).
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = ["main", "build_parser"]


# ----------------------------------------------------------------------------------------
# argument types: a bad number is a usage error (exit 2), never a crash later on
# ----------------------------------------------------------------------------------------
def _num(lo=None, hi=None, *, lo_open=False, hi_open=False, integer=False):
    """argparse ``type=`` for a finite number in [lo, hi] (open ends with ``*_open``)."""

    def conv(text):
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if integer else 'a number'}, got {text!r}") from None
        if not np.isfinite(v):
            raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
        if (lo is not None and (v < lo or (lo_open and v == lo))) or \
                (hi is not None and (v > hi or (hi_open and v == hi))):
            rng = (f"{'(' if lo_open else '['}{'-inf' if lo is None else lo}, "
                   f"{'inf' if hi is None else hi}{')' if hi_open else ']'}")
            raise argparse.ArgumentTypeError(f"{text} is out of range; allowed: {rng}")
        return v

    conv.__name__ = "integer" if integer else "number"
    return conv


_SEED = _num(0, 2**63 - 1, integer=True)


# ----------------------------------------------------------------------------------------
# self-check (foundation)
# ----------------------------------------------------------------------------------------
def _cmd_selfcheck(args) -> int:
    from .selfcheck import run_selfcheck

    ok = run_selfcheck(verbose=not args.quiet)
    return 0 if ok else 1


def _register_core(sub) -> None:
    p = sub.add_parser(
        "selfcheck",
        help="check the installation: rotation algebra, dynamics, ephemeris files",
        description="Run quick numerical self-checks of the installed package (rotation "
        "algebra against scipy, angular-momentum conservation of the rigid-body integrator, "
        "offline ephemeris availability) and print one line per check.",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="print only failures")
    p.set_defaults(func=_cmd_selfcheck)


# ----------------------------------------------------------------------------------------
# geometry (sites)
# ----------------------------------------------------------------------------------------
def _cmd_sites_list(args) -> int:
    from .geometry.sites import load_sites

    sites = load_sites(args.sites)
    if not sites:
        print("no sites found")
        return 0
    print(f"{'id':<16} {'lat_deg':>10} {'lon_deg':>11} {'height_m':>9}  band  name")
    for sid in sorted(sites):
        s = sites[sid]
        print(f"{s.id:<16} {s.lat_deg:>10.4f} {s.lon_deg:>11.4f} {s.height_m:>9.1f}  "
              f"{s.band:<4}  {s.name}")
    return 0


def _cmd_sites_show(args) -> int:
    from .geometry.sites import get_site

    print(get_site(args.id, args.sites).describe())
    return 0


def _register_geometry(sub) -> None:
    p = sub.add_parser(
        "sites",
        help="list or show observing sites (observatories/*.toml)",
        description="The site catalog: the bundled observatories/ folder plus any folders "
        "given with --sites (later folders override earlier ones). Each site is one TOML "
        "file with id, name, lat_deg, lon_deg (WGS84), height_m and optional band and "
        "[horizon_mask].",
    )
    ssub = p.add_subparsers(title="sites commands", metavar="SUBCOMMAND")
    pl = ssub.add_parser("list", help="list all known sites")
    pl.add_argument("--sites", action="append", metavar="DIR", default=None,
                    help="extra folder of site TOML files (repeatable)")
    pl.set_defaults(func=_cmd_sites_list)
    ps = ssub.add_parser("show", help="show one site")
    ps.add_argument("id", help="site id, e.g. socorro")
    ps.add_argument("--sites", action="append", metavar="DIR", default=None,
                    help="extra folder of site TOML files (repeatable)")
    ps.set_defaults(func=_cmd_sites_show)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


# ----------------------------------------------------------------------------------------
# photometry (shapes)
# ----------------------------------------------------------------------------------------
def _cmd_shapes_list(args) -> int:
    from .photometry.shapes_io import load_shape, shape_library

    for name, path in shape_library(args.library).items():
        try:
            desc = load_shape(path).description
        except InputError as exc:
            desc = f"(invalid: {exc.bare_message})"
        print(f"{name:20s} {desc}")
    return 0


def _cmd_shapes_show(args) -> int:
    from .photometry.shapes_io import load_shape

    print(load_shape(args.name, library_dirs=args.library).summary())
    return 0


def _cmd_shapes_validate(args) -> int:
    from .photometry.shapes_io import validate_shape

    problems = validate_shape(args.spec, library_dirs=args.library)
    for p in problems:
        print(p)
    if not problems:
        print(f"{args.spec}: OK")
    # non-convexity alone is a warning (exit 0); anything else is a problem (exit 2)
    from .photometry.shapes_io import NONCONVEX_NOTE

    return 2 if any(NONCONVEX_NOTE not in p for p in problems) else 0


def _register_photometry(sub) -> None:
    p = sub.add_parser(
        "shapes",
        help="list, show and validate faceted shapes",
        description="Faceted shape library: bundled shapes/ plus folders given with --library. "
        "Shapes are TOML facet lists or OBJ/STL meshes with a TOML material map.",
    )
    p.add_argument("--library", action="append", metavar="DIR", default=None,
                   help="extra shape folder searched before the bundled library (repeatable)")
    ssub = p.add_subparsers(title="shape commands", metavar="ACTION")
    pl = ssub.add_parser("list", help="list the shapes in the library")
    pl.set_defaults(func=_cmd_shapes_list)
    ps = ssub.add_parser("show", help="print a shape's facets, materials and mass properties")
    ps.add_argument("name", help="library name or path to a shape TOML")
    ps.set_defaults(func=_cmd_shapes_show)
    pv = ssub.add_parser(
        "validate", help="check a shape: degenerate facets, normals, material ranges, convexity",
        description="Report zero-area or degenerate facets, non-unit normals, materials outside "
        "their ranges (xi in [0,1], a in (0,1), m in (0,1]) and non-convex shapes (self-shadowing "
        "is not modelled). Exit code 0: no problems (or only non-convexity); 2: problems.")
    pv.add_argument("spec", metavar="PATH_OR_NAME", help="library name or path to a shape TOML")
    pv.set_defaults(func=_cmd_shapes_validate)
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])


# ----------------------------------------------------------------------------------------
# simulation, plotting
# ----------------------------------------------------------------------------------------
def _cmd_simulate(args) -> int:
    import warnings

    from .io.lightcurve_h5 import Lightcurve  # noqa: F401
    from .studies.scenario import load_scenario
    from .studies.simulate import simulate

    scen = load_scenario(args.scenario, library_dirs=args.library, site_dirs=args.sites)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lc, counts = simulate(scen, seed=args.seed, return_counts=True)
    for w in caught:
        print(f"WARNING: {w.message}", file=sys.stderr)
    lc.write(args.output)
    print(f"wrote {args.output}: {len(lc)} measurements from {len(lc.site_names)} site(s) "
          f"({counts.scheduled} scheduled; dropped {counts.below_horizon} below the elevation limit, "
          f"{counts.site_daylight} in site daylight, {counts.eclipsed} eclipsed)")
    if args.plot:
        from .report.plots import plot_lightcurve

        png = Path(args.output).with_suffix(".png")
        plot_lightcurve(lc, png, title=scen.name)
        print(f"wrote {png}")
    return 0


def _cmd_plot(args) -> int:
    from .io.lightcurve_h5 import read_lightcurve
    from .report.plots import plot_lightcurve

    lc = read_lightcurve(args.file)
    out = Path(args.output) if args.output else Path(args.file).with_suffix(".png")
    plot_lightcurve(lc, out, title=Path(args.file).name)
    print(f"wrote {out}")
    return 0


def _cmd_demo(args) -> int:
    import warnings

    from ._paths import data_dir
    from .report.plots import plot_lightcurve
    from .studies.scenario import load_scenario
    from .studies.simulate import simulate

    scen_path = Path(args.scenario) if args.scenario else data_dir("pipelines") / "default.toml"
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    scen = load_scenario(scen_path)
    print(f"scenario {scen_path} ({scen.name})")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lc = simulate(scen)
    for w in caught:
        print(f"WARNING: {w.message}", file=sys.stderr)
    from .io.paths import safe_output_path

    # the scenario name comes from a data file: it must not steer the output out of OUT
    h5 = lc.write(safe_output_path(out, scen.name, ".h5", field="scenario.name"))
    png = safe_output_path(out, scen.name, ".png", field="scenario.name")
    plot_lightcurve(lc, png, title=scen.name)
    print(f"simulated {len(lc)} magnitudes: {np.nanmin(lc.mag):.2f} to {np.nanmax(lc.mag):.2f} mag")
    print(f"wrote {h5}\nwrote {png}")
    if args.method == "none":
        return 0
    from .filters.invert import invert
    from .filters.plots import plot_estimate

    # invert the simulated lightcurve as in Bernard ch. 9: the filter starts from the truth
    # perturbed by sigma_theta / sigma_omega (drawn from the seed)
    est = invert(lc, args.method, seed=scen.seed, sigma_theta_deg=args.sigma_theta_deg,
                 sigma_omega_deg_s=args.sigma_omega_deg_s)
    res = est.write(safe_output_path(out, f"{scen.name}.{args.method}", ".h5", field="scenario.name"))
    epng = safe_output_path(out, f"{scen.name}.{args.method}", ".png", field="scenario.name")
    plot_estimate(est, epng, title=f"{scen.name} ({args.method})")
    s = est.summary()
    print(f"{args.method}: {len(est)} epochs in {est.runtime_s:.2f} s; final RSS attitude error "
          f"{s.get('final_att_error_rss_deg', float('nan')):.3f} deg, rate error "
          f"{s.get('final_omega_error_rss_deg_s', float('nan')):.4f} deg/s; all components inside "
          f"3 sigma: {'yes' if s.get('inside_3sigma') else 'no'}"
          + (f"; DIVERGED ({est.divergence_reason})" if est.diverged else ""))
    print(f"wrote {res}\nwrote {epng}")
    return 1 if est.diverged else 0


def _register_simulation(sub) -> None:
    p = sub.add_parser(
        "simulate", help="simulate a lightcurve from a scenario TOML",
        description="Simulate apparent magnitudes of a faceted spacecraft seen from one or more "
        "ground sites (Bernard 2021 ch. 5, consistent form) and write the HDF5 lightcurve "
        "(docs/formats.md) atomically.")
    p.add_argument("scenario", help="scenario TOML file (see docs/formats.md and pipelines/)")
    p.add_argument("-o", "--output", required=True, help="output HDF5 file")
    p.add_argument("--seed", type=_SEED, default=None, help="override [scenario].seed")
    p.add_argument("--plot", action="store_true", help="also write OUTPUT.png")
    p.add_argument("--library", action="append", default=None, metavar="DIR",
                   help="extra shape library folder (repeatable)")
    p.add_argument("--sites", action="append", default=None, metavar="DIR",
                   help="extra observatory folder (repeatable)")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("plot", help="plot a lightcurve HDF5 file to PNG",
                       description="Draw magnitude versus time per site, with the noise-free truth, "
                       "error bars, shadow flags and object elevation.")
    p.add_argument("file", help="lightcurve HDF5 file")
    p.add_argument("-o", "--output", default=None, help="PNG path (default: FILE.png)")
    p.set_defaults(func=_cmd_plot)

    p = sub.add_parser("demo", help="the main job: simulate the bundled default scenario, invert it, plot both",
                       description="Simulate the bundled default scenario (pipelines/default.toml, "
                       "Bernard's LEO fast-spin case seen from Socorro), invert it with an attitude "
                       "filter (UKF by default) and write the lightcurve, the estimate and PNG plots "
                       "into the output folder.")
    p.add_argument("-o", "--output", default="out", help="output folder (default: out)")
    p.add_argument("--scenario", default=None, help="another scenario TOML instead of the default")
    p.add_argument("--method", default="ukf", choices=("ukf", "mekf", "bpf", "none"),
                   help="attitude filter used to invert the simulated lightcurve (default ukf; "
                   "none: simulate only)")
    p.add_argument("--sigma-theta-deg", type=float, default=3.0,
                   help="1-sigma initial attitude error per axis, deg (default 3, Bernard ch. 9)")
    p.add_argument("--sigma-omega-deg-s", type=float, default=0.02,
                   help="1-sigma initial rate error per axis, deg/s (default 0.02)")
    p.set_defaults(func=_cmd_demo)


# ----------------------------------------------------------------------------------------
# coarse sun sensors
# ----------------------------------------------------------------------------------------
def _css_sensors(name, fov_deg):
    from .css.configurations import configuration_by_name

    if name in ("dual_pyramid", "cube"):
        return configuration_by_name(name, fov_half_angle_deg=fov_deg)
    return configuration_by_name(name)


def _css_albedo(spec):
    from .css.albedo import load_albedo_map

    if spec == "builtin":
        return None
    if spec == "none":
        return False
    return load_albedo_map(spec)


def _cmd_css_simulate(args) -> int:
    import numpy as np

    from .css.recording import write_recording
    from .css.study import gyroless_params, settled_mask
    from .css.sunline_ekf import FilterParams
    from .css.truth import Scenario, simulate

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
    import numpy as np

    from .css.recording import read_recording
    from .css.single_point import angle_deg, estimate
    from .css.study import gyroless_params
    from .css.sunline_ekf import FilterParams, run_filter

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
        from .io.atomic import atomic_path

        with atomic_path(args.out, suffix=".csv") as tmp:
            np.savetxt(tmp, np.column_stack([rec["t"], s_hat]), delimiter=",",
                       header="t_s,s_hat_x,s_hat_y,s_hat_z (body axes)", comments="")
        print(f"wrote {args.out}")
    return 0


def _cmd_css_study(args) -> int:
    from dataclasses import replace

    from .css.study import load_study, run_study, write_report

    spec = load_study(args.pipeline)
    if args.runs is not None:
        spec = replace(spec, n_runs=args.runs)
    cases = run_study(spec)
    if args.out:
        out_dir = args.out
    else:  # derived from the study's name (data): keep it inside the current folder
        from .io.paths import safe_output_path

        out_dir = safe_output_path(".", f"{spec.name}-report", field="study.name")
    out = write_report(spec, cases, out_dir)
    print((out / "summary.txt").read_text(), end="")
    print(f"report in {out}/ (summary.json, summary.txt, envelopes.png, error_maps.png)")
    return 0


def _register_css(sub) -> None:
    p = sub.add_parser(
        "css", help="coarse sun sensors: simulate, estimate the Sun direction, Monte Carlo studies",
        description="Coarse-sun-sensor (CSS) tools after O'Keefe (2015): cosine sensors with "
        "Earth albedo, rate gyros, single-point (WAVG/LSMN/WLSMN) and sequential (EKF/ECKF) "
        "sun-direction estimators and MRP sun-pointing control.")
    css_sub = p.add_subparsers(title="css commands", metavar="CSS_COMMAND")

    def common(q):
        q.add_argument("--config", default="dual_pyramid",
                       help="sensor set: dual_pyramid, cube or a sensor TOML file (default dual_pyramid)")
        q.add_argument("--fov-deg", type=_num(0.0, 90.0, lo_open=True), default=70.0,
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
    s.add_argument("--duration-s", type=_num(0.0, 366 * 86400.0, lo_open=True), default=1800.0, help="duration, s (default 1800)")
    s.add_argument("--dt-s", type=_num(1e-3, 60.0), default=0.5, help="sample and control step, s (default 0.5)")
    s.add_argument("--epoch", default="2015-03-01T00:00:00Z", help="epoch, ISO 8601 UTC")
    s.add_argument("--albedo", default="builtin",
                   help="builtin (zonal CERES fit), none, or a CERES CSV / TOMS .dat file")
    s.add_argument("--filter-albedo", default="builtin",
                   help="albedo model inside the EKF/ECKF: builtin (default), none (no albedo "
                   "model, first-session filter), or a CERES CSV / TOMS .dat file")
    s.add_argument("--seed", type=_SEED, default=1, help="random seed (default 1)")
    s.add_argument("--settle-s", type=_num(0.0), default=300.0,
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
    e.add_argument("--threshold", type=_num(), default=0.5,
                   help="activity threshold of the single-point methods (default 0.5)")
    e.add_argument("--settle-s", type=_num(0.0), default=300.0, help="skip this long before scoring, s")
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
    st.add_argument("--runs", type=_num(1, 100000, integer=True), help="override the number of runs")
    st.add_argument("--out", help="report folder (default <study name>-report)")
    st.set_defaults(func=_cmd_css_study)

    # --- issue 9: calibration, fault detection, VMM/SMM, Sun models (handlers in
    # lightcurve/css/cli_tools.py) ---
    def _lazy(name):
        def run(args):
            from .css import cli_tools

            return getattr(cli_tools, name)(args)
        return run

    ca = css_sub.add_parser(
        "calibrate", help="on-orbit CSS calibration filters (full and reduced) on a simulated orbit",
        description="Simulate O'Keefe's §4.4 case (one orbit, tumbling, dual pyramid, scale "
        "factors dispersed 30 %%, misalignments, albedo, gyro, star tracker) and run the full "
        "calibration ECKF (MRP, gyro bias, scale factors, misalignments, albedo model) and the "
        "reduced filter (albedo as a considered bias). Prints per-sensor errors and 3-sigma bounds.")
    ca.add_argument("--filter", choices=("full", "reduced", "both"), default="both")
    ca.add_argument("--seed", type=_SEED, default=0, help="random seed (default 0)")
    ca.add_argument("--duration-s", type=_num(10.0, 86400.0), default=None,
                    help="duration, s (default one 400 km orbit, 5553 s)")
    ca.add_argument("--dt-s", type=_num(0.05, 10.0), default=1.0, help="step, s (default 1)")
    ca.add_argument("--scale-sigma", type=_num(0.0, 1.0), default=0.3,
                    help="1-sigma dispersion of the scale factors (default 0.3)")
    ca.add_argument("--misalignment-sigma-deg", type=_num(0.0, 20.0), default=2.0,
                    help="1-sigma misalignment per angle, deg (default 2)")
    ca.add_argument("--star-period-s", type=_num(0.0, 3600.0), default=10.0,
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
    fa.add_argument("--runs", type=_num(1, 100000, integer=True), default=300,
                    help="runs per failure mode (default 300)")
    fa.add_argument("--workers", type=_num(1, 256, integer=True), default=1)
    fa.add_argument("--seed", type=_SEED, default=0)
    fa.add_argument("--window", type=_num(1, 100000, integer=True), default=50,
                    help="averaging window, valid samples (default 50)")
    fa.add_argument("--prob", type=_num(0.0, 1.0, lo_open=True, hi_open=True), default=0.999999,
                    help="probability of the chi-square interval (default 1-1e-6)")
    fa.add_argument("--start-s", type=_num(0.0), default=600.0,
                    help="no decision before this time, s (default 600)")
    fa.add_argument("--fail-s", type=_num(0.0), default=1950.0, help="failure time, s (default 1950)")
    fa.add_argument("--no-dark", action="store_true",
                    help="averaged NIS only: switch off the dark-sensor test (a lit sensor whose "
                    "output stays at zero; catches off failures of never-calibrated sensors)")
    fa.add_argument("--star-period-s", type=_num(0.0, 3600.0), default=10.0,
                    help="star-tracker period, s; 0 for none (default 10)")
    fa.add_argument("--out", help="write the summary to this JSON file")
    fa.set_defaults(func=_lazy("cmd_faults"))

    vm = css_sub.add_parser(
        "vmm", help="voltage vs sun-vector measurement model in a full-attitude MEKF",
        description="DiGregorio's comparison: MEKF with magnetometer, gyro and photodiodes, "
        "photodiodes used as a least-squares Sun vector (SMM) or as individual voltages (VMM); "
        "attitude errors grouped by the number of lit photodiodes, with a plot.")
    vm.add_argument("--runs", type=_num(1, 100000, integer=True), default=20)
    vm.add_argument("--seed", type=_SEED, default=0)
    vm.add_argument("--duration-s", type=_num(10.0, 86400.0), default=3000.0)
    vm.add_argument("--fov-deg", type=_num(0.0, 90.0, lo_open=True), default=70.0,
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


# ----------------------------------------------------------------------------------------
# attitude filters (invert)
# ----------------------------------------------------------------------------------------
def _csv_list(text, option):
    """Split a comma-separated CLI value into stripped, non-empty items (InputError if none)."""
    items = tuple(x.strip() for x in str(text).split(",") if x.strip())
    if not items:
        raise InputError("needs at least one comma-separated value", field=option,
                         value=text)
    return items


def _csv_ints(text, option):
    """Comma-separated non-negative integers (facet indices) from a CLI value."""
    out = []
    for x in _csv_list(text, option):
        try:
            v = int(x)
        except ValueError:
            v = -1
        if v < 0 or str(v) != x.lstrip("+"):
            raise InputError("not a non-negative integer", field=option, value=x,
                             allowed="0-based facet indices, e.g. 0,2,5")
        out.append(v)
    return tuple(out)


def _cmd_invert(args) -> int:
    from .studies.batch import expand_inputs, invert_files

    n_files = len(expand_inputs(args.files))  # a pattern matching nothing: InputError, exit 2
    bar = n_files > 1 and not args.quiet

    def report(text, kind="info"):
        if kind == "info":
            line, stream = text, sys.stdout
        else:
            line, stream = f"lightcurve: {kind}: {text}", sys.stderr
        if bar:
            from tqdm import tqdm

            tqdm.write(line, file=stream)
        else:
            print(line, file=stream)

    res = invert_files(args.files, args.method, args.output, workers=args.workers,
                       scheduler=args.scheduler, dask_local=args.dask_local, progress=bar,
                       plot=args.plot, report=report, seed=args.seed,
                       sigma_theta_deg=args.sigma_theta_deg,
                       sigma_omega_deg_s=args.sigma_omega_deg_s, particles=args.particles,
                       roughening=args.roughening, resampling=args.resampling,
                       rejuvenation=args.rejuvenation,
                       ess_threshold=args.ess_threshold, acs_mode=args.acs_mode,
                       pseudo_noise=args.pseudo_noise, alpha=args.alpha, beta=args.beta,
                       kappa=args.kappa, reflection=args.reflection,
                       attitude="truth" if args.attitude_known else "estimate",
                       reflection_frac=args.reflection_frac,
                       reflection_kinds=_csv_list(args.reflection_params, "--reflection-params"),
                       reflection_facets=(None if args.reflection_facets is None else
                                          _csv_ints(args.reflection_facets,
                                                    "--reflection-facets")),
                       gate={"mode": args.gate, "false_alarm": args.gate_false_alarm})
    out = Path(args.output)
    print(f"wrote {out / 'summary.json'} ({res['n_files']} file(s), {res['n_diverged']} diverged, "
          f"{res['n_input_errors']} rejected, {res['n_failed'] - res['n_input_errors']} failed)")
    # exit 2 when an input was rejected (bad file or setting), 1 when a run failed otherwise
    return 2 if res["n_input_errors"] else (1 if res["n_failed"] else 0)


def _register_filters(sub) -> None:
    p = sub.add_parser(
        "invert",
        help="estimate attitude and rate from lightcurve files (MEKF, UKF, particle filter)",
        description="Run an attitude filter on each lightcurve HDF5 file and write one result "
        "HDF5 per input plus DIR/summary.json (per file: method, final RSS attitude and rate "
        "error, final 3-sigma bounds, whether every component ended inside 3 sigma, "
        "divergence flag, runtime; or the error of a file that failed — the others go on). "
        "The initial estimate is the file's truth perturbed by --sigma-theta-deg / "
        "--sigma-omega-deg-s using --seed (Bernard 2021 ch. 9). Many files run in parallel on "
        "the executors of 'compare' (process pool, Dask); the results do not depend on the "
        "executor. Exit code 2 if an input was rejected, 1 if a run failed.")
    p.add_argument("files", nargs="+", metavar="FILE.h5",
                   help="lightcurve HDF5 file(s) or glob patterns (expanded here, so quoted "
                   "patterns work; a pattern matching nothing is an error)")
    ex = p.add_mutually_exclusive_group()
    ex.add_argument("--workers", type=_num(1, 4096, integer=True), default=None,
                    help="local process-pool size (default: one per CPU, at most one per file; "
                    "1 runs in this process)")
    ex.add_argument("--scheduler", metavar="ADDRESS", default=None,
                    help="address of an existing Dask scheduler, e.g. tcp://10.0.0.5:8786")
    ex.add_argument("--dask-local", type=_num(1, 4096, integer=True), default=None, metavar="W",
                    help="start a Dask LocalCluster with W worker processes")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("--method", choices=("mekf", "ukf", "bpf"), default="ukf",
                   help="filter (default: ukf)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=_SEED, default=0, help="random seed (default 0)")
    p.add_argument("--sigma-theta-deg", type=_num(0.0, 180.0, lo_open=True), default=3.0,
                   help="1-sigma initial attitude error per axis, deg (default 3)")
    p.add_argument("--sigma-omega-deg-s", type=_num(0.0, lo_open=True), default=0.02,
                   help="1-sigma initial rate error per axis, deg/s (default 0.02)")
    p.add_argument("--particles", type=_num(2, 10_000_000, integer=True), default=10_000, help="BPF particles (default 10000)")
    p.add_argument("--roughening", type=_num(0.0), default=0.2,
                   help="BPF roughening constant G (Bernard table 7.9; used with --rejuvenation "
                   "separate; default 0.2)")
    p.add_argument("--resampling", choices=("systematic", "multinomial"), default="systematic")
    p.add_argument("--rejuvenation", choices=("auto", "separate", "joint"), default="auto",
                   help="BPF: how the resampled cloud is moved: joint = one Liu-West kernel on "
                   "the whole state with the Musso et al. (2001) bandwidth; separate = the "
                   "table-7.9 roughening of attitude and rate (uses --roughening); auto = joint "
                   "when the attitude is estimated (default)")
    p.add_argument("--ess-threshold", type=_num(0.0, 1.0), default=0.5,
                   help="BPF: resample when N_eff < threshold * N (default 0.5)")
    p.add_argument("--acs-mode", choices=("random_walk", "jitter"), default="random_walk",
                   help="controlled model: ACS noise as attitude random walk or jitter")
    p.add_argument("--pseudo-noise", type=_num(0.0), default=0.0,
                   help="rate pseudo-noise PSD, (rad/s)^2/s (default 0)")
    p.add_argument("--alpha", type=_num(0.0, lo_open=True), default=1.0, help="UKF alpha (default 1)")
    p.add_argument("--beta", type=_num(), default=2.0, help="UKF beta (default 2)")
    p.add_argument("--kappa", type=_num(), default=0.0, help="UKF kappa (default 0)")
    p.add_argument("--reflection", choices=("none", "random-walk", "model1", "model2", "model3"),
                   default="none",
                   help="states for uncertain reflection parameters (Bernard ch. 8): per-site "
                   "magnitude biases (random-walk, model1, model2) or the facet parameters "
                   "xi, a, m, A themselves (model3); MEKF, UKF and particle filter "
                   "(default none)")
    p.add_argument("--reflection-params", default="xi,a,m,A", metavar="LIST",
                   help="model3: comma-separated parameters to estimate per facet, from xi "
                   "(diffuse fraction), a (albedo = F0), m (Beckmann slope), A (area) "
                   "(default xi,a,m,A). a and A reach the magnitude almost only as the product "
                   "a*A (diffuse term, and the specular term near normal incidence): estimated "
                   "together with equal priors neither shrinks by more than ~sqrt(2); leave A "
                   "out when the areas are known to make a observable")
    p.add_argument("--reflection-facets", default=None, metavar="LIST",
                   help="model3: comma-separated facet indices (0-based, shape-file order) "
                   "whose parameters are estimated (default: every Cook-Torrance facet)")
    p.add_argument("--reflection-frac", type=_num(0.0, lo_open=True), default=0.1,
                   help="relative 1-sigma of the reflection parameters: prior of model3, "
                   "eq. 8.10 bias variance of model1/2 (default 0.1 = Bernard sec. 10.1)")
    p.add_argument("--attitude-known", action="store_true",
                   help="hold attitude and rate at the file's truth and estimate only the "
                   "reflection states (thesis sec. 10.7 parameter-only runs; needs --reflection)")
    p.add_argument("--gate", choices=("auto", "reject", "inflate", "off"), default="auto",
                   help="innovation (outlier) gate: skip a magnitude whose normalised innovation "
                   "squared exceeds the chi-square threshold (reject), use it with inflated noise "
                   "(inflate), or no gate; auto = reject in the UKF, inflate in the MEKF and the "
                   "particle filter (default auto; counts in summary.json)")
    p.add_argument("--gate-false-alarm", type=_num(0.0, 0.5, lo_open=True), default=1e-4,
                   help="probability that the gate flags a good magnitude (default 1e-4: "
                   "NIS > 15.14)")
    p.add_argument("--plot", action="store_true", help="also write a PNG per file")
    p.set_defaults(func=_cmd_invert)


def _cmd_diagnose(args) -> int:
    from .diagnosis.diagnose import diagnose_recording
    from .diagnosis.report import write_report

    say = (lambda m: None) if args.quiet else (lambda m: print(m, flush=True))
    d = diagnose_recording(args.recording, args.scenario, free=args.free,
                           exclude=[e.strip() for e in (args.exclude or "").split(",") if e.strip()],
                           cross_validation=False if args.no_cv else None, progress=say,
                           max_effects=args.max_effects, seed=args.seed)
    jpath, hpath = write_report(d, args.output)
    js = d.summary()
    print(f"verdict: {js['verdict']}; baseline chi2/dof {js['baseline']['chi2_dof']:.3g}; chosen: "
          f"{', '.join(js['chosen']) or 'none'}; final chi2/dof {js['final']['chi2_dof']:.3g}")
    cv = js.get("cross_validation")
    if cv:
        print(f"leave-one-night-out ({cv['n_folds']} nights): RMS {cv['rms_mag_before']:.3f} -> "
              f"{cv['rms_mag_after']:.3f} mag, R {cv['r_before']:.3f} -> {cv['r_after']:.3f}")
    print(f"wrote {jpath} and {hpath}")
    return 0


def _register_diagnosis(sub) -> None:
    p = sub.add_parser(
        "diagnose", help="find where a model and a recording differ and name the missing physics",
        description="Fit the model's baseline to a recording, test the residuals (chi-square band, "
        "Ljung-Box, runs, systematic segments), score every registered physics effect (signature "
        "correlation, fit, delta-BIC), fit the best one or two, and write DIR/diagnosis.json and "
        "DIR/report.html. Recordings spanning several nights get leave-one-night-out "
        "cross-validation. A coarse-sun-sensor recording (HDF5 from 'css simulate', detected from "
        "the file) is diagnosed against its sensors' direct-Sun model with the css_* effects.")
    p.add_argument("recording", help="lightcurve HDF5 file, CSS recording HDF5, or a CSV recording "
                   "(needs --scenario)")
    p.add_argument("--scenario", default=None, metavar="MODEL.toml",
                   help="the model (scenario TOML; its [effects] are switched off; an optional "
                   "[diagnosis] table sets free/exclude/max_effects/min_delta_bic). Default for HDF5: "
                   "the file's own scenario. For a CSS recording: optionally a CSS sensor "
                   "configuration TOML (the model's nominal sensors; default: the file's)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    p.add_argument("--free", default=None,
                   help="free baseline parameters: none | zero_point | reflection | BRDF parameter "
                   "names, comma separated (default: none for HDF5 with truth, reflection for CSV)")
    p.add_argument("--exclude", default=None, help="effects not to propose, comma separated")
    p.add_argument("--max-effects", type=_num(1, 2, integer=True), default=None,
                   help="at most this many effects in the final model (1 or 2; default 2)")
    p.add_argument("--no-cv", action="store_true", help="skip the leave-one-night-out cross-validation")
    p.add_argument("--seed", type=_SEED, default=0, help="seed of the random fit starts (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(func=_cmd_diagnose)


# ----------------------------------------------------------------------------------------
# studies (issue 7): Monte Carlo filter comparisons
# ----------------------------------------------------------------------------------------
def _cmd_compare(args) -> int:
    from .studies.runner import run_study
    from .studies.study import load_study

    study = load_study(args.study)
    summary = run_study(study, args.output, runs=args.runs, workers=args.workers,
                        scheduler=args.scheduler, dask_local=args.dask_local, force=args.force,
                        progress=not args.quiet)
    cells = summary["cells"]
    cnt = {c: sum(1 for x in cells if x["color"] == c) for c in ("green", "yellow", "red")}
    fails = sum(x["failures"] for x in cells)
    print(f"{len(cells)} cells x {summary['runs_per_cell']} runs: {cnt['green']} green, "
          f"{cnt['yellow']} yellow, {cnt['red']} red; {fails} failed runs")
    print(f"wrote {Path(args.output) / 'summary.json'} and {Path(args.output) / 'report.html'}")
    return 0


def _register_studies(sub) -> None:
    p = sub.add_parser(
        "compare",
        help="run a Monte Carlo filter-comparison study (resumable; process pool or Dask)",
        description="Run every cell of a study TOML (grid of filters, dynamics, sites, initial "
        "errors, noise levels) RUNS times: simulate, invert, score. Each finished run is stored "
        "under DIR/runs/ as it completes; rerunning the same command resumes. Writes "
        "DIR/summary.json and a self-contained DIR/report.html (Bernard 2021 fig. 9.4 table). "
        "Results do not depend on the executor or the worker count.")
    p.add_argument("study", metavar="STUDY.toml", help="study file (docs/formats.md, Studies)")
    p.add_argument("--runs", type=_num(1, 1_000_000, integer=True), default=None,
                   help="runs per cell (default: the study's [study] runs)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    ex = p.add_mutually_exclusive_group()
    ex.add_argument("--workers", type=_num(1, 4096, integer=True), default=None,
                    help="local process-pool size (default: all CPUs; 1 runs in this process)")
    ex.add_argument("--scheduler", metavar="ADDRESS", default=None,
                    help="address of an existing Dask scheduler, e.g. tcp://10.0.0.5:8786")
    ex.add_argument("--dask-local", type=_num(1, 4096, integer=True), default=None, metavar="W",
                    help="start a Dask LocalCluster with W worker processes")
    p.add_argument("--force", action="store_true",
                   help="discard stored runs of a different (changed) study instead of refusing")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_compare)


def _cmd_fit_reflection(args) -> int:
    import json

    from .io.lightcurve_h5 import read_lightcurve
    from .io.paths import safe_output_path
    from .studies.fit_reflection import ConvergenceError, fit_reflection

    if args.attitude == "estimate" and not args.estimate:
        raise InputError("--attitude estimate needs --estimate FILE.h5 (an 'invert' result)",
                         field="--estimate")
    curve = read_lightcurve(args.file)
    kinds = _csv_list(args.params, "--params")
    facets = list(_csv_ints(args.facets, "--facets")) if args.facets else None
    say = (lambda n, d: None) if args.quiet else (
        lambda n, d: print(f"  {n} steps: max tau {d.as_dict()['tau_max_steps']:.1f}, "
                           f"acceptance {d.mean_acceptance:.2f}", flush=True))
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    stem = Path(args.file).stem
    try:
        fit = fit_reflection(curve, shape=args.shape, attitude=args.attitude,
                             estimate=args.estimate, facets=facets, kinds=kinds,
                             prior_frac=args.prior_frac, walkers=args.walkers, seed=args.seed,
                             max_steps=args.max_steps, tau_factor=args.tau_factor,
                             progress=say)
    except ConvergenceError as exc:
        from .io.atomic import atomic_write_text

        dpath = safe_output_path(out, f"{stem}.reflection.diagnostics", ".json", field="file name")
        atomic_write_text(dpath, json.dumps({"converged": False,
                                             "diagnostics": exc.diagnostics.as_dict()}, indent=2))
        print(f"lightcurve: {exc}", file=sys.stderr)
        print(f"no posterior reported; diagnostics in {dpath}", file=sys.stderr)
        return 1
    jpath = fit.write_json(safe_output_path(out, f"{stem}.reflection", ".json", field="file name"))
    cpath = fit.corner_plot(safe_output_path(out, f"{stem}.reflection.corner", ".png",
                                             field="file name"))
    ppath = fit.predictive_plot(safe_output_path(out, f"{stem}.reflection.predictive", ".png",
                                                 field="file name"))
    s = fit.summary()
    d = s["diagnostics"]
    if "attitude_warning" in s["meta"]:
        print(f"warning: {s['meta']['attitude_warning']}", file=sys.stderr)
    print(f"converged: {d['n_steps']} steps, max tau {d['tau_max_steps']:.1f}, acceptance "
          f"{d['mean_acceptance']:.2f}, {s['n_samples']} samples")
    for r in s["parameters"]:
        print(f"  {r['name']:>8s}  median {r['median']:.4g}  [{r['q005']:.4g}, {r['q995']:.4g}] "
              f"(99%)  post/prior width {r['width_ratio']:.2f}"
              f"{'  identified' if r['identified'] else ''}"
              + (f"  truth {r['truth']:.4g}{'' if r['truth_in_99'] else ' OUTSIDE 99%'}"
                 if "truth" in r else ""))
    print(f"posterior-predictive 95% coverage of the measurements: {s['predictive_coverage_95']:.3f}")
    print(f"wrote {jpath}, {cpath}, {ppath}")
    return 0


def _register_reflection(sub) -> None:
    p = sub.add_parser(
        "fit-reflection",
        help="MCMC (emcee) posterior of facet reflection parameters given a known attitude",
        description="Sample the posterior of the Cook-Torrance parameters (xi, a, m) and areas "
        "of the shape's facets from one lightcurve HDF5 file with the attitude held fixed "
        "(the file's truth or an 'invert' estimate). Unbounded coordinates: logit for xi and a, "
        "log for m and A; Gaussian prior centred on the shape file's values with sigma = "
        "--prior-frac times the value. Refuses (exit 1) to report a posterior whose chain has "
        "not converged (autocorrelation time, acceptance) and says why. Writes "
        "DIR/STEM.reflection.json (posterior table, identifiability, diagnostics), a corner "
        "plot and a posterior-predictive lightcurve PNG.")
    p.add_argument("file", metavar="FILE.h5", help="lightcurve HDF5 file")
    p.add_argument("--attitude", choices=("truth", "estimate"), default="truth",
                   help="attitude history to hold fixed (default: truth)")
    p.add_argument("--estimate", metavar="EST.h5", help="'invert' result file for --attitude estimate")
    p.add_argument("--shape", help="shape name or TOML (default: the file's attrs['shape'])")
    p.add_argument("--params", default="xi,a,m,A",
                   help="comma-separated parameters per facet among xi,a,m,A (default: all)")
    p.add_argument("--facets", help="comma-separated facet indices (default: every Cook-Torrance facet)")
    p.add_argument("--prior-frac", type=_num(0.0, 10.0, lo_open=True), default=0.1,
                   help="prior 1-sigma as a fraction of the nominal value (default 0.1)")
    p.add_argument("--walkers", type=_num(4, 100_000, integer=True), default=None,
                   help="ensemble walkers (default max(2D+2, 32))")
    p.add_argument("--max-steps", type=_num(500, 10_000_000, integer=True), default=40_000,
                   help="step budget (default 40000)")
    p.add_argument("--tau-factor", type=_num(1.0), default=50.0,
                   help="converged when steps >= factor x max autocorrelation time (default 50)")
    p.add_argument("--seed", type=_SEED, default=0, help="random seed (default 0)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=_cmd_fit_reflection)


_REGISTRARS = (_register_core, _register_geometry, _register_photometry, _register_simulation,
               _register_css, _register_filters, _register_diagnosis, _register_studies,
               _register_reflection)


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every registered subcommand."""
    parser = argparse.ArgumentParser(
        prog="lightcurve",
        description="Simulate and invert photometric lightcurves of spacecraft; coarse sun "
        "sensor estimation. Run 'lightcurve COMMAND --help' for each command.",
    )
    parser.add_argument("--debug", action="store_true", help="print full tracebacks on errors")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND")
    for reg in _REGISTRARS:
        reg(sub)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``lightcurve`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except InputError as exc:  # bad input: exit 2
        if args.debug:
            traceback.print_exc()
        print(f"lightcurve: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("lightcurve: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `lightcurve ... | head`: the reader went away, not our failure
        try:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115  silence the flush at exit
        except OSError:
            pass
        return 0
    except Exception as exc:  # run-time failure: exit 1, one line unless --debug
        if args.debug:
            traceback.print_exc()
        hint = "" if args.debug else " (run with --debug for details)"
        print(f"lightcurve: failed: {type(exc).__name__}: {_one_line(exc)}{hint}", file=sys.stderr)
        return 1


def _one_line(exc: BaseException, limit: int = 2000) -> str:
    """The exception's text on one line (newlines folded), at most ``limit`` characters."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
