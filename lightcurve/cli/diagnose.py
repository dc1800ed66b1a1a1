"""``lightcurve diagnose``: locate model/recording mismatches and name the missing physics;
``--apply FIT.json``: apply a fitted model unchanged to a new recording."""

from __future__ import annotations

from ._args import (add_command, add_model_options, add_output, add_quiet, add_seed, csv_list,
                    naming_file, number, report_written)

__all__ = ["register"]


def _cmd_diagnose(args) -> int:
    """Test the residuals of a recording against its model (chi-square band, Ljung-Box, runs,
    systematic segments), fit every registered physics effect and a refit of the object's
    surfaces as candidates, and add them greedily by their gain on held-out data (blocked
    cross-validation over objects, nights, passes or time blocks — whatever the recording has);
    an effect is named only when its parameters are identified. Writes DIR/diagnosis.json and
    DIR/report.html. With --apply FIT.json the fitted model of an earlier diagnosis is applied
    unchanged to this recording and the report says whether it transfers (DIR/transfer.json,
    DIR/transfer.html). A coarse-sun-sensor recording (HDF5 from 'css simulate', detected from
    the file) is diagnosed against its sensors' direct-Sun model with the css_* effects.
    """
    from ..diagnosis.folds import GROUPINGS
    from ..errors import InputError
    from ..studies.runner import limit_blas_threads

    # the diagnosis fits are small dense least-squares problems: threaded BLAS only spins
    limit_blas_threads()

    say = (lambda m: None) if args.quiet else (lambda m: print(m, flush=True))
    if args.apply is not None:
        from ..diagnosis.transfer import apply_fit, write_transfer_report

        tr = apply_fit(args.apply, args.recording, args.scenario, shape=args.shape,
                       library_dirs=args.library, site_dirs=args.sites)
        jp, hp = write_transfer_report(tr, args.output)
        for r in tr.rows:
            ok = "" if r["transfers"] is None else ("  transfers" if r["transfers"] else "  does NOT transfer")
            print(f"{r['component']:>24}: RMS {r['rms']:.4f}, chi2/dof {r['chi2_dof']:.3g}, "
                  f"R {r['r']:.3f}{ok}")
        print(tr.verdict)
        return report_written(jp, hp)
    from ..diagnosis.diagnose import diagnose_recording
    from ..diagnosis.report import write_report

    groups = csv_list(args.cv, "--cv")
    for g in groups:
        if g not in ("auto", "none") + GROUPINGS:
            raise InputError("unknown cross-validation grouping", field="--cv", value=g,
                             allowed="auto, none, " + ", ".join(GROUPINGS))
    folds = None if groups[0] == "none" else groups[0]
    with naming_file(args.recording[0] if len(args.recording) == 1 else ", ".join(args.recording)):
        d = diagnose_recording(args.recording, args.scenario, free=args.free,
                               exclude=[e.strip() for e in (args.exclude or "").split(",")
                                        if e.strip()],
                               folds=folds, n_folds=args.folds, cv_report=tuple(groups[1:]),
                               progress=say, max_effects=args.max_effects,
                               min_gain=args.min_gain, seed=args.seed, shape=args.shape,
                               library_dirs=args.library, site_dirs=args.sites)
    jpath, hpath = write_report(d, args.output)
    js = d.summary()
    print(js["verdict_line"])
    print(f"model as given: chi2/dof {js['baseline']['chi2_dof']:.3g}, RMS {js['baseline']['rms']:.4g}; "
          f"final: chi2/dof {js['final']['chi2_dof']:.3g}, RMS {js['final']['rms']:.4g}")
    cv = js["cross_validation"]
    if not cv.get("possible"):
        print(f"no cross-validation: {cv.get('reason')}")
    for sch in cv.get("schemes", []):
        if sch.get("possible"):
            print(f"held out ({sch['method']}, {sch['n_groups']} in {sch['n_folds']} folds): RMS "
                  f"{sch['baseline']['rms']:.3f} -> {sch['final']['rms']:.3f}, R "
                  f"{sch['baseline']['r']:.3f} -> {sch['final']['r']:.3f}")
        else:
            print(f"held out ({sch['grouping']}): {sch['reason']}")
    for u in js["unidentified"]:
        print(f"fits, but unidentifiable with these data: {u['name']} ({'; '.join(u['reasons'][:2])})")
    return report_written(jpath, hpath)


def register(sub) -> None:
    p = add_command(
        sub, "diagnose", _cmd_diagnose,
        help="find where a model and a recording differ and name the missing physics")
    p.add_argument("recording", nargs="+",
                   help="lightcurve HDF5 file, CSS recording HDF5, or a CSV recording (needs "
                   "--scenario); several lightcurve files (one object each, as 'lightcurve "
                   "import' writes them) are diagnosed together, and objects can be held out")
    p.add_argument("--scenario", default=None, metavar="MODEL.toml",
                   help="the model (scenario TOML; its [effects] are switched off; an optional "
                   "[diagnosis] table sets free/exclude/max_effects/min_gain). Default for HDF5: "
                   "the file's own scenario (with the shape and sites the file carries). For a "
                   "CSS recording: optionally a CSS sensor "
                   "configuration TOML (the model's nominal sensors; default: the file's)")
    add_output(p, required=True, help="output folder (diagnosis.json and report.html, or "
               "transfer.json and transfer.html with --apply)")
    p.add_argument("--apply", default=None, metavar="FIT.json",
                   help="apply the fitted model of this diagnosis.json unchanged to RECORDING and "
                   "report, component by component, whether it transfers (nothing is refitted)")
    p.add_argument("--free", default=None,
                   help="free baseline parameters: none | zero_point | reflection | BRDF parameter "
                   "names, comma separated (default: none; the surface refit is a candidate)")
    p.add_argument("--exclude", default=None,
                   help="candidates not to propose (effect names or 'surface'), comma separated")
    p.add_argument("--max-effects", type=number(1, 2, integer=True), default=None,
                   help="at most this many effects in the final model (1 or 2; default 2)")
    p.add_argument("--cv", default="auto", metavar="GROUPING[,GROUPING...]",
                   help="cross-validation grouping for choosing effects: auto (objects, else "
                   "nights, else passes, else time blocks), objects, nights, passes, cameras, sites, "
                   "blocks, or none (choose by in-sample delta-BIC); further groupings after a comma "
                   "are only reported (e.g. 'nights,objects'). Default auto")
    p.add_argument("--folds", type=number(2, 100, integer=True), default=5,
                   help="number of cross-validation folds (default 5)")
    p.add_argument("--min-gain", type=number(0, None, lo_open=True), default=None,
                   help="held-out gain G needed to add an effect (default 10)")
    add_seed(p, default=0, help="seed of the random fit starts")
    add_quiet(p, help="no progress messages")
    add_model_options(p)
