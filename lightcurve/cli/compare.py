"""``lightcurve compare``: Monte Carlo filter-comparison studies."""

from __future__ import annotations

from pathlib import Path

from ._args import (add_command, add_device, add_executors, add_model_options, add_output,
                    add_quiet, number, report_written)

__all__ = ["register"]


def _cmd_compare(args) -> int:
    """Run every cell of a study TOML (grid of filters, dynamics, sites, initial errors, noise
    levels) RUNS times: simulate, invert, score. Each finished run is stored under DIR/runs/ as
    it completes; rerunning the same command resumes. Writes DIR/summary.json and a
    self-contained DIR/report.html (Bernard 2021 fig. 9.4 table). Results do not depend on the
    executor or the worker count.
    """
    from ..studies.runner import run_study
    from ..studies.study import load_study

    study = load_study(args.study, library_dirs=args.library, site_dirs=args.sites)
    summary = run_study(study, args.output, runs=args.runs, workers=args.workers,
                        scheduler=args.scheduler, dask_local=args.dask_local, force=args.force,
                        progress=not args.quiet, device=args.device)
    cells = summary["cells"]
    cnt = {c: sum(1 for x in cells if x["color"] == c) for c in ("green", "yellow", "red")}
    fails = sum(x["failures"] for x in cells)
    ind = " (INDICATIVE: fewer than 100 runs per cell, thresholds scaled)" \
        if summary.get("indicative") else ""
    print(f"{len(cells)} cells x {summary['runs_per_cell']} runs: {cnt['green']} green, "
          f"{cnt['yellow']} yellow, {cnt['red']} red; {fails} failed runs{ind}")
    agr = summary.get("agreement")
    if agr is not None:
        byf = ", ".join(f"{f} {v['agree']}/{v['compared']}" for f, v in agr["by_filter"].items())
        pct = 100.0 * agr["agree"] / agr["compared"] if agr["compared"] else float("nan")
        print(f"Bernard (2021) Fig. {summary['thesis_figure']}, {summary.get('variant')} "
              f"variant: {agr['agree']} of {agr['compared']} run cells agree ({pct:.0f} %; "
              f"{byf}){ind}")
        if "self_agree" in agr:
            from ..studies.agreement import spread_text

            print(spread_text(agr))
    return report_written(Path(args.output) / "summary.json", Path(args.output) / "report.html")


def register(sub) -> None:
    p = add_command(
        sub, "compare", _cmd_compare, resume_hint="finished runs are kept in {output}/runs; run "
        "the same command again to resume",
        help="run a Monte Carlo filter-comparison study (resumable; process pool or Dask)")
    p.add_argument("study", metavar="STUDY.toml", help="study file (docs/formats.md, Studies)")
    p.add_argument("--runs", type=number(1, 1_000_000, integer=True), default=None,
                   help="runs per cell (default: the study's [study] runs)")
    add_output(p, what="folder", required=True,
               help="output folder (runs/, summary.json, report.html; reused to resume)")
    add_executors(p, workers_help="local process-pool size (default: all CPUs; 1 runs in this "
                  "process)")
    p.add_argument("--force", action="store_true",
                   help="discard stored runs of a different (changed) study instead of refusing")
    add_quiet(p, help="no progress bar")
    add_model_options(p, shape=False)
    add_device(p)
