"""Batch inversion: one attitude filter over many lightcurve files, on the study executors.

``lightcurve invert FILE_OR_GLOB… -o DIR [--workers W | --scheduler ADDRESS | --dask-local W]``
calls :func:`invert_files`. Patterns are expanded here (:func:`expand_inputs`, so a quoted
``"data/*.h5"`` works the same as one the shell expanded); a pattern with wildcards that
matches nothing is an error naming the pattern. Every file is one task run by
:func:`lightcurve.studies.runner.iter_results` (the executors of ``lightcurve compare``: local
process pool, Dask ``LocalCluster`` or an existing Dask scheduler); the worker reads the file
and runs :func:`lightcurve.filters.invert` (seeded with the same ``seed`` for every file, so
the result depends only on the file and the settings — identical on every executor), and the
main process writes each result as it arrives to ``DIR/<stem>.<method>.h5`` (through
:func:`lightcurve.io.paths.safe_output_path`; inputs whose stems collide get ``-2``, ``-3``…
in input order). A failing file does not stop the others: its error is recorded in
``DIR/summary.json`` (key = output stem; ``error`` and ``error_kind``: ``"input"`` for a bad
input file or setting, or an output that would replace an input, ``"output"`` for a result
that could not be written, ``"runtime"`` for anything else). ``summary.json`` is written
even when the batch is interrupted (the files finished so far). The output folder is locked
while the batch runs (:mod:`lightcurve.io.locks`).
"""

from __future__ import annotations

import glob
import os
import time
import traceback
import uuid
import warnings
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

__all__ = ["expand_inputs", "InvertTask", "execute_invert_task", "invert_files"]

_GLOB_CHARS = set("*?[")


def expand_inputs(patterns) -> list:
    """Input paths from file names and glob patterns, in the order given (duplicates dropped).

    A pattern with ``*``, ``?`` or ``[`` is expanded with :func:`glob.glob` (``**`` recursive),
    sorted; one that matches no file raises :class:`~lightcurve.errors.InputError` naming it.
    A plain name is kept as given, existing or not (reading it reports a missing file for
    that input alone). Returns a list of :class:`pathlib.Path`.
    """
    out, seen = [], set()
    for pat in patterns:
        pat = str(pat)
        if _GLOB_CHARS & set(pat):
            hits = sorted(p for p in glob.glob(os.path.expanduser(pat), recursive=True)
                          if os.path.isfile(p))
            if not hits:
                raise InputError("the pattern matches no file", field="FILE", value=pat,
                                 allowed="a file name or a glob pattern matching files")
        else:
            hits = [pat]
        for h in hits:
            key = os.path.abspath(h)
            if key not in seen:
                seen.add(key)
                out.append(Path(h))
    return out


@dataclass(frozen=True)
class InvertTask:
    """One file of a batch inversion (picklable).

    ``key`` is the output stem (unique in the batch), ``options`` the sorted keyword
    arguments of :func:`lightcurve.filters.invert` (besides the curve and the method).
    """

    key: str
    file: str
    method: str
    options: tuple = ()

    @property
    def run_id(self) -> str:
        return self.key


def execute_invert_task(task: InvertTask) -> dict:
    """Read ``task.file`` and invert it (executed in a worker). Never raises.

    Returns
    -------
    dict
        ``key``, ``file``, ``status`` ("ok" or "failed"), ``error`` (one-line text),
        ``error_kind`` ("input" for an :class:`~lightcurve.errors.InputError`, else
        "runtime"), ``traceback``, ``wall_s``, and on success ``estimate`` (the
        :class:`~lightcurve.filters.result.Estimate`).
    """
    from ..filters.invert import invert
    from ..io.lightcurve_h5 import read_lightcurve

    t0 = time.perf_counter()
    res = {"key": task.key, "file": task.file, "status": "ok", "error": "", "error_kind": "",
           "traceback": "", "estimate": None}
    try:
        curve = read_lightcurve(task.file)
        # messages about the scenario stored in the file name this file (a stored "file"
        # attribute is the sender's, not a path here)
        curve.attrs["file"] = str(task.file)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            res["estimate"] = invert(curve, task.method, **dict(task.options))
        res["estimate"].source_file = str(task.file)
    except InputError as exc:  # the message always names the input file
        text = str(exc)
        if task.file not in text:
            text = f"{task.file}: {text}"
        res.update(status="failed", error=text, error_kind="input")
    except Exception as exc:  # noqa: BLE001 - one failing file must not stop the batch
        res.update(status="failed", error=f"{type(exc).__name__}: {exc}", error_kind="runtime",
                   traceback=traceback.format_exc(limit=8))
    res["wall_s"] = time.perf_counter() - t0
    return res


def _unique_keys(files) -> list:
    """Output stems: the file-name-safe stems, ``-2``, ``-3``… appended to repeats."""
    from ..io.paths import safe_name

    keys, used = [], set()
    for f in files:
        try:
            stem = safe_name(Path(f).stem, field="file name")
        except InputError:
            stem = "lightcurve"
        k, i = stem, 1
        while k in used:
            i += 1
            k = f"{stem}-{i}"
        used.add(k)
        keys.append(k)
    return keys


def invert_files(patterns, method: str, out_dir, *, workers: int | None = None,
                 scheduler: str | None = None, dask_local: int | None = None,
                 progress: bool = True, plot: bool = False, report=None, **invert_options) -> dict:
    """Invert every file matched by ``patterns`` with ``method``; write results and a summary.

    Parameters
    ----------
    patterns : iterable of str — file names and glob patterns (:func:`expand_inputs`)
    method : str — "mekf", "ukf" or "bpf"
    out_dir : path — output folder (created)
    workers, scheduler, dask_local : the executor (:func:`lightcurve.studies.runner.iter_results`);
        default: inline for one file, else a process pool of ``min(files, os.cpu_count())``
    progress : bool — tqdm progress bar on stderr (files done, failures, time left)
    plot : bool — also write ``DIR/<stem>.<method>.png`` per result
    report : callable ``(text, kind) -> None``, optional — one line per finished file;
        ``kind`` is "info", "error" (bad input) or "failed" (run-time failure)
    **invert_options : keyword arguments of :func:`lightcurve.filters.invert` (seed,
        sigma_theta_deg, sigma_omega_deg_s, particles, reflection …), the same for every file

    Returns
    -------
    dict
        ``summary`` (key → per-file summary dict, input order, as written to
        ``DIR/summary.json``), ``n_files``, ``n_failed``, ``n_input_errors``, ``n_diverged``.

    Raises
    ------
    InputError
        A pattern matches no file, or more than one executor is given.
    """
    import json

    from ..io.atomic import atomic_write_text, clean_stale_temp
    from ..io.paths import safe_output_path
    from .runner import iter_results, limit_blas_threads, progress_bar

    from ..io.locks import folder_lock

    files = expand_inputs(patterns)
    if not files:
        raise InputError("no input files", field="FILE", allowed="one or more files or patterns")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    opts = tuple(sorted(invert_options.items()))
    tasks = [InvertTask(k, str(f), method, opts) for k, f in zip(_unique_keys(files), files)]
    if workers is None and scheduler is None and dask_local is None:
        workers = max(1, min(len(tasks), os.cpu_count() or 1))
    say = report or (lambda text, kind="info": None)
    results = {}
    counts = {"fail": 0, "input": 0, "div": 0}

    def failed(k, file, error, kind, tb=""):
        counts["fail"] += 1
        counts["input"] += kind == "input"
        results[k] = {"file": file, "method": method, "error": error, "error_kind": kind}
        if tb:
            results[k]["traceback"] = tb
        say(error if kind == "input" else f"{file}: {error}",
            "error" if kind == "input" else "failed")

    with folder_lock(out, what="output folder"):
        clean_stale_temp(out)
        # an output that would replace an input (x.ukf.h5 given as input next to x.h5):
        # that file fails as bad input; it is not run and nothing is overwritten
        outputs = {t.key: [safe_output_path(out, f"{t.key}.{method}", s, field="file name")
                           for s in (".h5",) + ((".png",) if plot else ())] for t in tasks}
        runnable = []
        for t in tasks:
            clash = next((p for p in outputs[t.key] for f in files if _same_file(p, f)), None)
            if clash is not None:
                failed(t.key, t.file, str(InputError(
                    "the output would overwrite an input file of this batch", file=clash,
                    field="output", allowed="an output folder without the inputs' result "
                    "names")), "input")
            else:
                runnable.append(t)
        limit_blas_threads()
        token = uuid.uuid4().hex[:12]  # unique Dask keys even when batches share a scheduler
        bar = progress_bar(len(tasks), initial=len(tasks) - len(runnable),
                           desc=f"invert {method}", progress=progress)
        it = iter_results(runnable, execute_invert_task, workers=workers, scheduler=scheduler,
                          dask_local=dask_local,
                          key=lambda t: f"lightcurve-invert-{token}-{t.key}")
        try:
            for res in it:
                k = res["key"]
                if res["status"] != "ok":
                    failed(k, res["file"], res["error"], res["error_kind"], res["traceback"])
                else:
                    _store(res, k, method, outputs[k], results, counts, say, failed)
                bar.set_postfix(failures=counts["fail"], refresh=False)
                bar.update(1)
        finally:
            close = getattr(it, "close", None)
            if close is not None:
                close()  # stops the executor now when interrupted
            bar.close()
            # written whatever happened: every finished file is recorded (an interrupted
            # batch lists the files done so far)
            summary = {t.key: results[t.key] for t in tasks if t.key in results}
            atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    return {"summary": summary, "n_files": len(tasks), "n_failed": counts["fail"],
            "n_input_errors": counts["input"], "n_diverged": counts["div"]}


def _same_file(a, b) -> bool:
    """True when paths ``a`` and ``b`` name one existing file (links and spellings count)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def _store(res, k, method, paths, results, counts, say, failed) -> None:
    """Write one file's estimate (and plot); a failed write is recorded for that file only."""
    est = res["estimate"]
    s = est.summary()
    s["file"] = res["file"]
    try:
        est.write(paths[0])
    except InputError as exc:
        failed(k, res["file"], str(exc), "input")
        return
    except OSError as exc:  # e.g. the result name is a folder, the disk is full
        failed(k, res["file"], f"cannot write the result {paths[0]}: {type(exc).__name__}: "
               f"{exc}", "output")
        return
    s["result"] = str(paths[0])
    results[k] = s
    counts["div"] += bool(est.diverged)
    say(_result_line(res["file"], method, est, s))
    if len(paths) > 1:
        from ..filters.plots import plot_estimate

        try:
            plot_estimate(est, paths[1], title=f"{k} ({method})")
        except OSError as exc:
            s["plot_error"] = f"cannot write the plot {paths[1]}: {type(exc).__name__}: {exc}"
            counts["fail"] += 1
            say(f"{res['file']}: {s['plot_error']}", "failed")
            return
        say(f"wrote {paths[1]}")


def _result_line(file, method, est, s) -> str:
    line = f"{file}: {method} {len(est)} epochs, {est.runtime_s:.2f} s"
    if "final_att_error_rss_deg" in s:
        line += (f", final RSS error {s['final_att_error_rss_deg']:.3f} deg / "
                 f"{s['final_omega_error_rss_deg_s']:.4f} deg/s, inside 3-sigma: "
                 f"{'yes' if s['inside_3sigma'] else 'no'}")
    else:  # no truth (a recording): the uncertainty reached and the innovation consistency
        import numpy as np

        nis = est.nis[np.isfinite(est.nis)]
        line += (f", final 3-sigma {max(s['final_3sigma_att_deg']):.3f} deg / "
                 f"{max(s['final_3sigma_omega_deg_s']):.4f} deg/s"
                 + (f", mean NIS {float(np.mean(nis)):.2f} (1 when consistent)" if nis.size else ""))
    if est.diverged:
        line += f", DIVERGED ({est.divergence_reason})"
    if est.skipped_nan:
        line += f", {est.skipped_nan} NaN magnitude(s) skipped"
    if getattr(est, "refl_names", None) is not None:
        line += f", {len(est.refl_names)} Model 3 facet parameters estimated"
    flags = (s.get("consistency") or {}).get("flags") or []
    if flags:
        line += f", FLAGGED: {', '.join(flags)} (the fit is not consistent with the noise)"
    gi = (est.meta or {}).get("global_init") if hasattr(est, "meta") else None
    if gi and gi.get("statement"):
        line += f"\n  global initialisation: {gi['statement']}"
    return line
