"""The ``lightcurve`` command line.

Each area registers its subcommands in one ``_register_<area>`` function below; handlers are
thin: they parse arguments, call the library and print. Exit codes: 0 success, 1 run-time
failure, 2 bad usage or bad input (one clear line; the traceback only with ``--debug``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = ["main", "build_parser"]


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
    h5 = lc.write(out / f"{scen.name}.h5")
    png = out / f"{scen.name}.png"
    plot_lightcurve(lc, png, title=scen.name)
    print(f"simulated {len(lc)} magnitudes: {np.nanmin(lc.mag):.2f} to {np.nanmax(lc.mag):.2f} mag")
    print(f"wrote {h5}\nwrote {png}")
    print("(attitude inversion joins this job when the filters land; see the issue tracker)")
    return 0


def _register_simulation(sub) -> None:
    p = sub.add_parser(
        "simulate", help="simulate a lightcurve from a scenario TOML",
        description="Simulate apparent magnitudes of a faceted spacecraft seen from one or more "
        "ground sites (Bernard 2021 ch. 5, consistent form) and write the HDF5 lightcurve "
        "(docs/formats.md) atomically.")
    p.add_argument("scenario", help="scenario TOML file (see docs/formats.md and pipelines/)")
    p.add_argument("-o", "--output", required=True, help="output HDF5 file")
    p.add_argument("--seed", type=int, default=None, help="override [scenario].seed")
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

    p = sub.add_parser("demo", help="the main job: simulate the bundled default scenario and plot it",
                       description="Simulate the bundled default scenario (pipelines/default.toml, "
                       "Bernard's LEO fast-spin case seen from Socorro) and write the lightcurve "
                       "HDF5 and a PNG plot into the output folder.")
    p.add_argument("-o", "--output", default="out", help="output folder (default: out)")
    p.add_argument("--scenario", default=None, help="another scenario TOML instead of the default")
    p.set_defaults(func=_cmd_demo)


# ----------------------------------------------------------------------------------------
# coarse sun sensors
# ----------------------------------------------------------------------------------------
def _register_css(sub) -> None:
    pass


# ----------------------------------------------------------------------------------------
# attitude filters (invert)
# ----------------------------------------------------------------------------------------
def _cmd_invert(args) -> int:
    import json

    from .filters.invert import invert
    from .io.atomic import atomic_write_text
    from .io.lightcurve_h5 import read_lightcurve

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    summary = {}
    failed = 0
    for f in args.files:
        curve = read_lightcurve(f)
        est = invert(curve, args.method, seed=args.seed, sigma_theta_deg=args.sigma_theta_deg,
                     sigma_omega_deg_s=args.sigma_omega_deg_s, particles=args.particles,
                     roughening=args.roughening, resampling=args.resampling,
                     ess_threshold=args.ess_threshold, acs_mode=args.acs_mode,
                     pseudo_noise=args.pseudo_noise, alpha=args.alpha, beta=args.beta,
                     kappa=args.kappa)
        stem = Path(f).stem
        res = out / f"{stem}.{args.method}.h5"
        est.write(res)
        s = est.summary()
        s["file"] = str(f)
        s["result"] = str(res)
        summary[stem] = s
        if est.diverged:
            failed += 1
        line = f"{f}: {args.method} {len(est)} epochs, {est.runtime_s:.2f} s"
        if "final_att_error_rss_deg" in s:
            line += (f", final RSS error {s['final_att_error_rss_deg']:.3f} deg / "
                     f"{s['final_omega_error_rss_deg_s']:.4f} deg/s, inside 3-sigma: "
                     f"{'yes' if s['inside_3sigma'] else 'no'}")
        if est.diverged:
            line += f", DIVERGED ({est.divergence_reason})"
        if est.skipped_nan:
            line += f", {est.skipped_nan} NaN magnitude(s) skipped"
        print(line)
        if args.plot:
            from .filters.plots import plot_estimate

            png = out / f"{stem}.{args.method}.png"
            plot_estimate(est, png, title=f"{stem} ({args.method})")
            print(f"wrote {png}")
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    print(f"wrote {out / 'summary.json'} ({len(summary)} file(s), {failed} diverged)")
    return 0


def _register_filters(sub) -> None:
    p = sub.add_parser(
        "invert",
        help="estimate attitude and rate from lightcurve files (MEKF, UKF, particle filter)",
        description="Run an attitude filter on each lightcurve HDF5 file and write one result "
        "HDF5 per input plus DIR/summary.json (per file: method, final RSS attitude and rate "
        "error, final 3-sigma bounds, whether every component ended inside 3 sigma, "
        "divergence flag, runtime). The initial estimate is the file's truth perturbed by "
        "--sigma-theta-deg / --sigma-omega-deg-s using --seed (Bernard 2021 ch. 9).")
    p.add_argument("files", nargs="+", metavar="FILE.h5", help="lightcurve HDF5 file(s)")
    p.add_argument("--method", choices=("mekf", "ukf", "bpf"), default="ukf",
                   help="filter (default: ukf)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--sigma-theta-deg", type=float, default=3.0,
                   help="1-sigma initial attitude error per axis, deg (default 3)")
    p.add_argument("--sigma-omega-deg-s", type=float, default=0.02,
                   help="1-sigma initial rate error per axis, deg/s (default 0.02)")
    p.add_argument("--particles", type=int, default=10_000, help="BPF particles (default 10000)")
    p.add_argument("--roughening", type=float, default=0.2,
                   help="BPF roughening constant G (Bernard table 7.9; default 0.2)")
    p.add_argument("--resampling", choices=("systematic", "multinomial"), default="systematic")
    p.add_argument("--ess-threshold", type=float, default=0.5,
                   help="BPF: resample when N_eff < threshold * N (default 0.5)")
    p.add_argument("--acs-mode", choices=("random_walk", "jitter"), default="random_walk",
                   help="controlled model: ACS noise as attitude random walk or jitter")
    p.add_argument("--pseudo-noise", type=float, default=0.0,
                   help="rate pseudo-noise PSD, (rad/s)^2/s (default 0)")
    p.add_argument("--alpha", type=float, default=1.0, help="UKF alpha (default 1)")
    p.add_argument("--beta", type=float, default=2.0, help="UKF beta (default 2)")
    p.add_argument("--kappa", type=float, default=0.0, help="UKF kappa (default 0)")
    p.add_argument("--plot", action="store_true", help="also write a PNG per file")
    p.set_defaults(func=_cmd_invert)


_REGISTRARS = (_register_core, _register_geometry, _register_photometry, _register_simulation,
               _register_css, _register_filters)


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
    except InputError as exc:
        if args.debug:
            raise
        print(f"lightcurve: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("lightcurve: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # run-time failure: one line unless --debug
        if args.debug:
            raise
        print(f"lightcurve: failed: {type(exc).__name__}: {exc} (run with --debug for details)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
