"""``lightcurve simulate``, ``plot`` and ``demo``: simulate and draw lightcurves."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ._args import SEED, output_not_input

__all__ = ["register"]


def _cmd_simulate(args) -> int:
    import warnings

    from ..io.lightcurve_h5 import Lightcurve  # noqa: F401
    from ..studies.scenario import load_scenario
    from ..studies.simulate import simulate

    output_not_input(args.output, args.scenario)
    if args.plot:
        output_not_input(Path(args.output).with_suffix(".png"), args.scenario, option="--plot")
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
        from ..report.plots import plot_lightcurve

        png = Path(args.output).with_suffix(".png")
        plot_lightcurve(lc, png, title=scen.name)
        print(f"wrote {png}")
    return 0


def _cmd_plot(args) -> int:
    from ..io.lightcurve_h5 import read_lightcurve
    from ..report.plots import plot_lightcurve

    out = Path(args.output) if args.output else Path(args.file).with_suffix(".png")
    output_not_input(out, args.file)
    lc = read_lightcurve(args.file)
    plot_lightcurve(lc, out, title=Path(args.file).name)
    print(f"wrote {out}")
    return 0


def _cmd_demo(args) -> int:
    import warnings

    from .._paths import data_dir
    from ..report.plots import plot_lightcurve
    from ..studies.scenario import load_scenario
    from ..studies.simulate import simulate

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
    from ..io.paths import safe_output_path

    # the scenario name comes from a data file: it must not steer the output out of OUT
    h5 = lc.write(safe_output_path(out, scen.name, ".h5", field="scenario.name"))
    png = safe_output_path(out, scen.name, ".png", field="scenario.name")
    plot_lightcurve(lc, png, title=scen.name)
    print(f"simulated {len(lc)} magnitudes: {np.nanmin(lc.mag):.2f} to {np.nanmax(lc.mag):.2f} mag")
    print(f"wrote {h5}\nwrote {png}")
    if args.method == "none":
        return 0
    from ..filters.invert import invert
    from ..filters.plots import plot_estimate

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


def register(sub) -> None:
    p = sub.add_parser(
        "simulate", help="simulate a lightcurve from a scenario TOML",
        description="Simulate apparent magnitudes of a faceted spacecraft seen from one or more "
        "ground sites (Bernard 2021 ch. 5, consistent form) and write the HDF5 lightcurve "
        "(docs/formats.md) atomically.")
    p.add_argument("scenario", help="scenario TOML file (see docs/formats.md and pipelines/)")
    p.add_argument("-o", "--output", required=True, help="output HDF5 file")
    p.add_argument("--seed", type=SEED, default=None, help="override [scenario].seed")
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
