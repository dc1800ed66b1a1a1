"""``lightcurve period``: spin-period analysis of a lightcurve file."""

from __future__ import annotations

import json
from pathlib import Path

from ._args import add_command, add_output, add_quiet, number, report_written

__all__ = ["register"]


def _cmd_period(args) -> int:
    """Find the spin period of a lightcurve: Lomb-Scargle and phase-dispersion minimisation
    periodograms of the distance-reduced, detrended magnitudes, a multi-harmonic least-squares
    fit choosing the period and the number of harmonics by BIC, the period's 1-sigma, the
    aliases that also fit, and the 99 % interval of the sidereal spin period including the
    synodic correction for the moving phase-angle bisector; then the spin period among the
    best period and its 2-4x multiples by the turn-to-turn rank correlation of the lightcurve. With -o DIR writes
    DIR/STEM.period.json and a periodogram PNG. The result seeds the rate prior of 'invert
    --initial global'.
    """
    from ..acquisition.period import analyse_period, truth_spin_period_s
    from ..errors import InputError
    from ..io.atomic import atomic_write_text
    from ..io.lightcurve_h5 import read_lightcurve
    from ..io.paths import safe_output_path

    curve = read_lightcurve(args.file)
    res = analyse_period(curve, min_period_s=args.min_period_s, max_period_s=args.max_period_s,
                         max_harmonics=args.max_harmonics, trend_degree=args.trend_degree,
                         clip_mad=None if args.clip_mad == 0 else args.clip_mad)
    lo, hi = res.interval_99_s
    if args.quiet:   # one line: the result and its verdict
        print(f"{args.file}: period {res.period_s:.5g} ± {res.period_sigma_s:.2g} s "
              f"(sidereal 99 %: {lo:.5g} to {hi:.5g} s, "
              f"{'significant' if res.significant else 'NOT significant'}"
              f"{', AMBIGUOUS' if res.ambiguous else ''})")
    else:
        _print_details(args, res, lo, hi)
    if args.output:
        out = Path(args.output)
        out.mkdir(parents=True, exist_ok=True)
        stem = Path(args.file).stem
        jpath = safe_output_path(out, f"{stem}.period", ".json", field="file name")
        atomic_write_text(jpath, json.dumps(res.summary(), indent=2))
        truth = None
        if curve.truth_omega_rad_s is not None:   # a simulation: mark the truth's period
            try:
                inertia = curve.resolve_shape().inertia_kg_m2
            except InputError:
                inertia = None
            truth = truth_spin_period_s(curve, inertia)
        ppath = res.plot(safe_output_path(out, f"{stem}.period", ".png", field="file name"),
                         title=Path(args.file).name, true_period_s=truth)
        if not args.quiet:
            report_written(jpath, ppath)
    return 0


def _print_details(args, res, lo, hi) -> None:
    """The full console report of one period analysis."""
    print(f"{args.file}: {res.n_points} magnitudes over {res.span_s:.1f} s")
    print(f"brightness (synodic) period {res.period_s:.5g} ± {res.period_sigma_s:.2g} s "
          f"({res.n_harmonics} harmonics, chi2/dof {res.chi2_dof:.3g}, false-alarm probability "
          f"{res.false_alarm_probability:.2g}: "
          f"{'significant' if res.significant else 'NOT significant'})")
    if not res.significant:
        print("NO significant period: the numbers below describe the best trial period, not a "
              "detection (the lightcurve may not repeat over this window; use --initial global "
              "with its broad rate prior rather than this period)")
    print(f"sidereal spin period, 99 %: {lo:.5g} to {hi:.5g} s (synodic bound "
          f"±{res.synodic_bound_s:.3g} s from the phase-angle bisector's "
          f"{res.summary()['pab_rate_deg_s']:.3g} deg/s)")
    if res.ambiguous:
        alt = ", ".join(f"{c['period_s']:.5g} s ({c['relation']}, 99 %: "
                        f"{c['interval_99_s'][0]:.5g}-{c['interval_99_s'][1]:.5g})"
                        for c in res.candidates[1:])
        print(f"AMBIGUOUS: these periods fit about as well (delta BIC <= 6): {alt}")
    if res.spin_turn_correlation:
        lo_s, hi_s = res.spin_interval_99_s
        alt = "; ".join(f"{c['period_s']:.5g} s ({c['relation']})" for c in res.spin_alternatives)
        print(f"spin period (turn-to-turn repetition) {res.spin_period_s:.5g} s "
              f"({res.spin_relation}), 99 %: {lo_s:.5g} to {hi_s:.5g} s"
              + (f"; not ruled out: {alt}" if alt else ""))
        if alt:
            ivs = " or ".join(f"{a:.5g}-{b:.5g}" for a, b in res.spin_set_99_s)
            print(f"spin period 99 % set (the lightcurve cannot tell these apart): {ivs} s")
    if res.n_clipped:
        print(f"{res.n_clipped} glint(s) winsorised at {args.clip_mad:g} robust sigma "
              "(--clip-mad 0 keeps them)")
    print(f"Lomb-Scargle peak {res.ls_period_s:.5g} s; PDM minimum {res.pdm_period_s:.5g} s")
    if res.aliases:
        print("aliases (period s, relation, delta BIC):")
        for a in res.aliases[:6]:
            print(f"  {a['period_s']:10.5g}  {a['relation']:<14s} {a['delta_bic']:10.1f}")


def register(sub) -> None:
    p = add_command(
        sub, "period", _cmd_period,
        help="spin-period analysis of a lightcurve (periodogram, aliases, uncertainty)")
    p.add_argument("file", metavar="FILE.h5", help="lightcurve HDF5 file")
    add_output(p, what="folder", help="folder for the JSON summary and the periodogram PNG "
               "(default: print only)")
    p.add_argument("--min-period-s", type=number(0.0, lo_open=True), default=None,
                   help="shortest period searched, s (default 2.5 x the median cadence)")
    p.add_argument("--max-period-s", type=number(0.0, lo_open=True), default=None,
                   help="longest period searched, s (default the span / 1.5)")
    p.add_argument("--max-harmonics", type=number(1, 20, integer=True), default=6,
                   help="most harmonics of the multi-harmonic model (default 6)")
    p.add_argument("--trend-degree", type=number(0, 6, integer=True), default=2,
                   help="degree of the per-site polynomial trend removed with the fit (default 2)")
    p.add_argument("--clip-mad", type=number(0.0, 100.0), default=3.0,
                   help="winsorise detrended magnitudes beyond this many robust sigma (specular "
                   "glints a few harmonics cannot follow); 0 keeps every value (default 3)")
    add_quiet(p, help="print one line: the period, its 99 %% interval and the verdict")
