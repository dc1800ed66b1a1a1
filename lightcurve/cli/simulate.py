"""``lightcurve simulate``, ``plot`` and ``demo``: simulate and draw lightcurves."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ..studies.scenario import SCENARIO_ALIASES, resolve_scenario
from ._args import (add_command, add_model_options, add_output, add_plot, add_quiet, add_seed,
                    number, output_not_input, report_written)

__all__ = ["register", "resolve_scenario", "SCENARIO_ALIASES"]

def _cmd_simulate(args) -> int:
    """Simulate apparent magnitudes of a faceted spacecraft seen from one or more ground sites
    (Bernard 2021 ch. 5, consistent form) and write the HDF5 lightcurve (docs/formats.md)
    atomically. The file carries the resolved shape, so later commands need no --library.
    """
    import warnings

    from ..studies.scenario import load_scenario
    from ..studies.simulate import simulate

    output_not_input(args.output, args.scenario)
    if args.plot:
        output_not_input(Path(args.output).with_suffix(".png"), args.scenario, option="--plot")
    shape = None
    if args.shape is not None:
        from ..photometry import load_shape

        shape = load_shape(args.shape, library_dirs=args.library)
    scen = load_scenario(resolve_scenario(args.scenario), library_dirs=args.library,
                         site_dirs=args.sites, shape=shape)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lc, counts = simulate(scen, seed=args.seed, return_counts=True)
    for w in caught:
        print(f"WARNING: {w.message}", file=sys.stderr)
    lc.write(args.output)
    print(f"wrote {args.output}: {len(lc)} measurements from {len(lc.site_names)} site(s) "
          f"({counts.scheduled} scheduled; dropped {counts.below_horizon} below the elevation limit, "
          f"{counts.site_daylight} in site daylight, {counts.eclipsed} eclipsed, "
          f"{counts.no_reflection} with no lit facet facing the observer)")
    if args.plot:
        from ..report.plots import plot_lightcurve

        png = Path(args.output).with_suffix(".png")
        plot_lightcurve(lc, png, title=scen.name)
        report_written(png)
    return 0


def _cmd_plot(args) -> int:
    """Draw a PNG figure of a lightcurve HDF5 (magnitude versus UTC per site), an estimate HDF5
    (attitude, rates, spin axis, fitted lightcurve, errors against the truth when known), a CSS
    recording HDF5, a 'css estimate' CSV, an invert or compare summary.json or a fit-reflection
    JSON. The kind is read from the file.
    """
    from ..report.plot_any import file_kind, plot_file

    if args.output:
        output_not_input(args.output, args.file)
    kind = file_kind(args.file)
    out = plot_file(args.file, args.output)
    return report_written(out, detail=f" ({kind.replace('-', ' ')} figure)")


def _pass_facts(lc):
    """Facts of the simulated pass for the demo's text: elevation range, lit share, Sun
    altitude at the sites (deg, from the file's GCRS geometry and the site's geodetic
    vertical), phase-angle range."""
    from ..geometry.frames import itrs_rotation

    el = np.degrees(lc.elevation_rad) if lc.elevation_rad is not None else None
    lit = lc.lit_fraction
    # Sun altitude at each site: the site's geodetic up vector in GCRS
    R = itrs_rotation(lc.epoch_utc, lc.t)               # (N,3,3) GCRS -> ITRS
    lat = np.radians(lc.site_lla_deg_m[lc.site, 0])
    lon = np.radians(lc.site_lla_deg_m[lc.site, 1])
    up_itrs = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], 1)
    up = np.einsum("nji,nj->ni", R, up_itrs)            # ITRS -> GCRS
    d = lc.r_sun_eci_m - lc.r_site_eci_m
    sun_alt = np.degrees(np.arcsin(np.sum(up * d, 1) / np.linalg.norm(d, axis=1)))
    return {"el": el, "lit": lit, "sun_alt": sun_alt, "phase": np.degrees(lc.phase_angle_rad)}


def _cmd_demo(args) -> int:
    """Simulate the bundled default scenario (pipelines/default.toml: a 1U CubeSat spinning at 4.2
    deg/s on a real, sunlit LEO pass over Socorro, NM, at dusk), invert it with an attitude
    filter (UKF by default) started off the truth, print what was found, and write the
    lightcurve, the estimate and their figures into the output folder. Bernard's thesis case
    (the object in the Earth's shadow, computed as if sunlit) is --scenario thesis.
    """
    import warnings

    from ..io.paths import safe_output_path
    from ..report.plots import plot_lightcurve
    from ..studies.scenario import load_scenario
    from ..studies.simulate import simulate

    scen_path = resolve_scenario(args.scenario)
    out = Path(args.output)
    scen = load_scenario(scen_path)
    say = (lambda *a: None) if args.quiet else print
    say("lightcurve demo: simulate a lightcurve, estimate the attitude from it, plot both")
    from .._paths import data_dir

    base = data_dir("pipelines").resolve()
    shown = scen_path
    if base in scen_path.resolve().parents:
        shown = f"bundled pipelines/{scen_path.resolve().relative_to(base)}"
    sh = scen.shape
    say(f"scenario  {scen.name}  ({shown})")
    say(f"  object  {getattr(sh, 'description', '') or getattr(sh, 'name', '')}; "
        f"{scen.attitude.dynamics} attitude, spinning at "
        f"{np.linalg.norm(scen.attitude.omega_deg_s):.2f} deg/s")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lc, counts = simulate(scen, seed=args.seed, return_counts=True)
    out.mkdir(parents=True, exist_ok=True)
    f = _pass_facts(lc)
    from ..report.style import utc_times

    tt = utc_times(lc.epoch_utc, lc.t)
    t0, t1 = str(tt[0])[:19].replace("T", " "), str(tt[-1])[11:19]
    sites = ", ".join(lc.site_names)
    lit = "object sunlit 100 %" if lc.lit_fraction is None or np.all(lc.lit_fraction >= 1) else \
        (f"object in the Earth's shadow at {np.mean(lc.lit_fraction < 1) * 100:.0f} % of the "
         f"epochs" + (" (magnitudes computed AS IF SUNLIT, as in the thesis)"
                      if int(lc.attrs.get("ignore_eclipse", 0)) else ""))
    say(f"  pass    {t0} to {t1} UTC from {sites}: elevation {np.nanmin(f['el']):.0f} to "
        f"{np.nanmax(f['el']):.0f} deg; {lit}; Sun {-np.max(f['sun_alt']):.0f} to "
        f"{-np.min(f['sun_alt']):.0f} deg below the horizon" if f["el"] is not None else "")
    for w in caught:
        print(f"WARNING: {w.message}", file=sys.stderr)
    noise = float(lc.attrs.get("r_percent", np.nan))
    dropped = []
    if counts.below_horizon:
        dropped.append(f"{counts.below_horizon} below the elevation limit")
    if counts.site_daylight:
        dropped.append(f"{counts.site_daylight} in site daylight")
    if counts.eclipsed:
        dropped.append(f"{counts.eclipsed} in the Earth's shadow")
    n_dark = int(lc.attrs.get("dropped_no_reflection", 0))
    if n_dark:
        dropped.append(f"{n_dark} with no sunlit face towards the observer")
    say(f"measured  {len(lc)} magnitudes, {np.nanmin(lc.mag):.1f} to {np.nanmax(lc.mag):.1f} mag "
        f"(noise {noise:g} %, 1σ ≈ {np.nanmedian(lc.mag_sigma):.2f} mag)"
        + (f"; epochs dropped: {', '.join(dropped)}" if dropped else ""))
    # the scenario name comes from a data file: it must not steer the output out of OUT
    h5 = lc.write(safe_output_path(out, scen.name, ".h5", field="scenario.name"))
    png = safe_output_path(out, scen.name, ".png", field="scenario.name")
    plot_lightcurve(lc, png, title=scen.name)
    files = [(h5, "the lightcurve (HDF5, docs/formats.md)"),
             (png, "its plot: magnitude versus UTC")]
    code = 0
    if args.method != "none":
        from ..filters.derived import spin_axis
        from ..filters.invert import invert
        from ..filters.plots import plot_estimate

        # the filter starts from the truth perturbed by sigma_theta / sigma_omega (drawn from
        # the seed), as in Bernard ch. 9
        seed = scen.seed if args.seed is None else args.seed
        est = invert(lc, args.method, seed=seed, sigma_theta_deg=args.sigma_theta_deg,
                     sigma_omega_deg_s=args.sigma_omega_deg_s)
        name = {"ukf": "UKF", "mekf": "MEKF", "bpf": "particle filter"}[args.method]
        s = est.summary()
        say(f"estimate  {name} started {args.sigma_theta_deg:g} deg / {args.sigma_omega_deg_s:g} "
            f"deg/s (1σ) off the truth: {len(est)} epochs in {est.runtime_s:.2f} s")
        s3 = 3 * np.linalg.norm(est.att_sigma_deg[-1])
        if "final_att_error_rss_deg" in s:
            ok = s["inside_3sigma"] and not est.diverged
            say(f"  final attitude error {s['final_att_error_rss_deg']:.2f} deg (3σ bound "
                f"{s3:.2f} deg), rate error {s['final_omega_error_rss_deg_s']:.3f} deg/s: "
                + ("consistent, inside 3σ" if ok else "NOT consistent (outside 3σ)"))
        sp = spin_axis(est.q[-1:], est.omega_rad_s[-1:], est.cov[-1:])
        line = (f"  spin {sp['rate_deg_s'][0]:.3f} ± {3 * sp['rate_sigma_deg_s'][0]:.3f} deg/s "
                f"about RA {sp['ra_deg'][0]:.1f}, Dec {sp['dec_deg'][0]:.1f} deg "
                f"(± {3 * sp['axis_sigma_deg'][0]:.1f} deg, 3σ)")
        if lc.has_truth:
            st = spin_axis(lc.truth_q[-1:], lc.truth_omega_rad_s[-1:])
            line += (f"; truth {st['rate_deg_s'][0]:.3f} deg/s about RA {st['ra_deg'][0]:.1f}, "
                     f"Dec {st['dec_deg'][0]:.1f}")
        say(line)
        if est.diverged:
            say(f"  DIVERGED: {est.divergence_reason}")
            code = 1
        res = est.write(safe_output_path(out, f"{scen.name}.{args.method}", ".h5",
                                         field="scenario.name"))
        epng = safe_output_path(out, f"{scen.name}.{args.method}", ".png", field="scenario.name")
        plot_estimate(est, epng, curve=lc)
        files += [(res, "the estimate (attitude, rate, covariance per epoch; HDF5)"),
                  (epng, "its plot: attitude, rates, spin axis, fitted lightcurve"
                   + (", errors against the truth" if lc.has_truth else ""))]
    say(f"files in {out}/:")
    w = max(len(p.name) for p, _ in files)
    for p, what in files:
        say(f"  {p.name:<{w}}  {what}")
    if args.method != "none":
        say(f"next: lightcurve plot {files[2][0]}   ·   lightcurve demo --scenario thesis   ·   "
            "README 'Using it'")
    return code


def register(sub) -> None:
    p = add_command(
        sub, "simulate", _cmd_simulate, help="simulate a lightcurve from a scenario TOML")
    p.add_argument("scenario", help="scenario TOML file, or a bundled name: "
                   + ", ".join(SCENARIO_ALIASES) + " or thesis/<case> (docs/formats.md)")
    add_output(p, what="file", required=True, help="output lightcurve HDF5 file")
    add_seed(p, default=None, help="random seed of the attitude and measurement noise")
    add_plot(p, help="also write OUTPUT.png (magnitude versus UTC)")
    add_model_options(p)

    p = add_command(
        sub, "plot", _cmd_plot,
        help="draw any file the tool writes (lightcurve, estimate, CSS recording, summary)")
    p.add_argument("file", help="a file written by lightcurve (kind detected from its content)")
    add_output(p, what="file", help="PNG path (default: FILE with the suffix .png)")

    p = add_command(
        sub, "demo", _cmd_demo,
        help="the main job: simulate a real lit pass, estimate the attitude, plot both")
    add_output(p, what="folder", default="out", help="output folder")
    p.add_argument("--scenario", default="default",
                   help="scenario TOML file or bundled name: " + ", ".join(SCENARIO_ALIASES)
                   + " or thesis/<case> (default: default)")
    p.add_argument("--method", default="ukf", choices=("ukf", "mekf", "bpf", "none"),
                   help="attitude filter used to invert the simulated lightcurve (default ukf; "
                   "none: simulate only)")
    add_seed(p, default=None, help="random seed of the simulation and of the filter's start")
    p.add_argument("--sigma-theta-deg", type=number(0.0, 180.0, lo_open=True), default=3.0,
                   help="1-sigma initial attitude error per axis, deg (default 3, Bernard ch. 9)")
    p.add_argument("--sigma-omega-deg-s", type=number(0.0, 360.0, lo_open=True), default=0.02,
                   help="1-sigma initial rate error per axis, deg/s (default 0.02)")
    add_quiet(p, help="print nothing (files are still written)")
