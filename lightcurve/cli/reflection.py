"""``lightcurve fit-reflection``: MCMC posterior of facet reflection parameters."""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import InputError
from ._args import (add_command, add_model_options, add_output, add_quiet, add_seed, csv_ints,
                    csv_list, naming_file, number, output_not_input, refuse_inapplicable,
                    report_written)

__all__ = ["register"]


def _cmd_fit_reflection(args) -> int:
    """Sample the posterior of the Cook-Torrance parameters (xi, a, m) and areas of the shape's
    facets from one lightcurve HDF5 file with the attitude held fixed (the file's truth or an
    'invert' estimate). Unbounded coordinates: logit for xi and a, log for m and A; Gaussian
    prior centred on the shape file's values with sigma = --prior-frac times the value. Refuses
    (exit 1) to report a posterior whose chain has not converged (autocorrelation time,
    acceptance) and says why. Writes DIR/STEM.reflection.json (posterior table, identifiability,
    diagnostics), a corner plot and a posterior-predictive lightcurve PNG.
    """
    import json

    from ..io.lightcurve_h5 import read_lightcurve
    from ..io.paths import safe_output_path
    from ..errors import ConvergenceError
    from ..studies.fit_reflection import fit_reflection

    refuse_inapplicable(args, "attitude", {"estimate": {"estimate"}})
    if args.attitude == "estimate" and not args.estimate:
        raise InputError("--attitude estimate needs --estimate FILE.h5 (an 'invert' result)",
                         field="--estimate")
    output_not_input(args.output, args.file, args.estimate)
    curve = read_lightcurve(args.file)
    kinds = csv_list(args.params, "--params")
    facets = list(csv_ints(args.facets, "--facets")) if args.facets else None
    say = (lambda n, d: None) if args.quiet else (
        lambda n, d: print(f"  {n} steps: max tau {d.as_dict()['tau_max_steps']:.1f}, "
                           f"acceptance {d.mean_acceptance:.2f}", flush=True))
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    stem = Path(args.file).stem
    try:
        with naming_file(args.file):
            fit = fit_reflection(curve, shape=args.shape, attitude=args.attitude,
                                 estimate=args.estimate, facets=facets, kinds=kinds,
                                 prior_frac=args.prior_frac, walkers=args.walkers,
                                 seed=args.seed, max_steps=args.max_steps,
                                 tau_factor=args.tau_factor, progress=say,
                                 library_dirs=args.library)
    except ConvergenceError as exc:
        from ..io.atomic import atomic_write_text

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
    return report_written(jpath, cpath, ppath)


def register(sub) -> None:
    p = add_command(
        sub, "fit-reflection", _cmd_fit_reflection,
        help="MCMC (emcee) posterior of facet reflection parameters given a known attitude")
    p.add_argument("file", metavar="FILE.h5", help="lightcurve HDF5 file")
    p.add_argument("--attitude", choices=("truth", "estimate"), default="truth",
                   help="attitude history to hold fixed (default: truth)")
    p.add_argument("--estimate", metavar="EST.h5", help="'invert' result file for --attitude estimate")
    add_model_options(p, sites=False)
    p.add_argument("--params", default="xi,a,m,A",
                   help="comma-separated parameters per facet among xi,a,m,A (default: all)")
    p.add_argument("--facets", help="comma-separated facet indices (default: every Cook-Torrance facet)")
    p.add_argument("--prior-frac", type=number(0.0, 10.0, lo_open=True), default=0.1,
                   help="prior 1-sigma as a fraction of the nominal value (default 0.1)")
    p.add_argument("--walkers", type=number(4, 100_000, integer=True), default=None,
                   help="ensemble walkers (default max(2D+2, 32))")
    p.add_argument("--max-steps", type=number(500, 10_000_000, integer=True), default=40_000,
                   help="step budget (default 40000)")
    p.add_argument("--tau-factor", type=number(1.0), default=50.0,
                   help="converged when steps >= factor x max autocorrelation time (default 50)")
    add_seed(p, default=0, help="random seed of the walkers")
    add_output(p, what="folder", required=True,
               help="output folder (STEM.reflection.json, corner and predictive plots)")
    add_quiet(p, help="no progress lines")
