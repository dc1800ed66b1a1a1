"""``lightcurve diagnose``: locate model/recording mismatches and name the missing physics."""

from __future__ import annotations

from ._args import SEED, add_model_options, number

__all__ = ["register"]


def _cmd_diagnose(args) -> int:
    from ..diagnosis.diagnose import diagnose_recording
    from ..diagnosis.report import write_report

    say = (lambda m: None) if args.quiet else (lambda m: print(m, flush=True))
    d = diagnose_recording(args.recording, args.scenario, free=args.free,
                           exclude=[e.strip() for e in (args.exclude or "").split(",") if e.strip()],
                           cross_validation=False if args.no_cv else None, progress=say,
                           max_effects=args.max_effects, seed=args.seed, shape=args.shape,
                           library_dirs=args.library, site_dirs=args.sites)
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


def register(sub) -> None:
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
                   "the file's own scenario (with the shape and sites the file carries). For a "
                   "CSS recording: optionally a CSS sensor "
                   "configuration TOML (the model's nominal sensors; default: the file's)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    p.add_argument("--free", default=None,
                   help="free baseline parameters: none | zero_point | reflection | BRDF parameter "
                   "names, comma separated (default: none for HDF5 with truth, reflection for CSV)")
    p.add_argument("--exclude", default=None, help="effects not to propose, comma separated")
    p.add_argument("--max-effects", type=number(1, 2, integer=True), default=None,
                   help="at most this many effects in the final model (1 or 2; default 2)")
    p.add_argument("--no-cv", action="store_true", help="skip the leave-one-night-out cross-validation")
    p.add_argument("--seed", type=SEED, default=0, help="seed of the random fit starts (default 0)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages")
    add_model_options(p)
    p.set_defaults(func=_cmd_diagnose)
