"""Run a study: simulate → invert → metrics for every run, in parallel, resumable.

Output folder ``DIR`` (formats in docs/formats.md, "Studies"):

``DIR/study.json``
    the study's hash (:func:`lightcurve.studies.study.study_hash`: study and scenario texts,
    package version and a hash of the package's source files), name, text and cells; a rerun
    with a changed study (or changed scenario files, or changed code) is refused unless
    ``force`` (which discards the stored runs).
``DIR/runs/<cell tag>_r<run>.h5``
    one small HDF5 per finished run, written atomically (temporary file, then rename) by the
    main process as soon as the run's result arrives; failures are stored too (``status =
    "failed"`` with the error text). A restarted study skips every run that has a file.
``DIR/summary.json`` and ``DIR/report.html``
    written when every run is stored (:func:`summarize`).

Executors (all give the same numbers: each run depends only on its seeds, which derive from the
study seed and the cell, see :mod:`lightcurve.studies.study`): a local process pool (default,
``workers``), a Dask ``LocalCluster`` started here (``dask_local`` worker processes) or an
existing Dask cluster (``scheduler="tcp://host:port"``). Dask is imported only for those two and
its absence is a clear error naming the ``distributed`` extra.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import json
import os
import time
import traceback
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path, atomic_write_text, clean_stale_temp
from ..io.study_folder import open_runs_folder, read_study_meta
from .metrics import cell_summary, run_metrics
from .study import GRID_KEYS, RunTask, Study

__all__ = ["limit_blas_threads", "init_worker", "execute_task", "run_study", "summarize", "write_run", "read_run", "finished_runs",
           "prepare_output", "iter_results", "progress_bar", "RUN_FORMAT"]

RUN_FORMAT = "lightcurve-study-run"
_SUMMARY_FORMAT = "lightcurve-study-summary"


# ----------------------------------------------------------------------------------------
# one run (executed in a worker)
# ----------------------------------------------------------------------------------------
_BLAS_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
_BLAS_SETTERS = ("openblas_set_num_threads", "scipy_openblas_set_num_threads",
                 "scipy_openblas_set_num_threads64_", "openblas_set_num_threads64_")


def limit_blas_threads() -> int:
    """Make BLAS single-threaded in this process and its future children.

    A study runs one filter per worker process; the filters' linear algebra is on 6×6 and
    smaller matrices, where a multi-threaded OpenBLAS spends most of its time synchronising
    threads (measured: the MEKF 6× slower on a loaded 2-core machine). Sets the usual
    environment variables (inherited by spawned workers, e.g. Dask's) and calls the
    ``*_set_num_threads(1)`` entry points of the OpenBLAS libraries already loaded (found in
    ``/proc/self/maps``; Linux only, silently skipped elsewhere). Returns how many libraries
    were limited.
    """
    import ctypes

    for k in _BLAS_ENV:
        os.environ[k] = "1"
    n = 0
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            libs = {ln.split()[-1] for ln in fh if "openblas" in ln.lower() and ".so" in ln}
    except OSError:
        return 0
    for lib in sorted(libs):
        try:
            h = ctypes.CDLL(lib)
        except OSError:
            continue
        for name in _BLAS_SETTERS:
            fn = getattr(h, name, None)
            if fn is not None:
                fn(ctypes.c_int(1))
                n += 1
                break
    return n


@functools.lru_cache(maxsize=16)
def _scenario(text: str, file: str, library_dirs: tuple = (), site_dirs: tuple = ()):
    from .scenario import parse_scenario

    return parse_scenario(text, file=file, library_dirs=library_dirs or None,
                          site_dirs=site_dirs or None)


@functools.lru_cache(maxsize=32)
def _lightcurve(text: str, file: str, r_percent: float, sim_seed: int,
                library_dirs: tuple = (), site_dirs: tuple = (), cook_torrance: str = "",
                truth_acs_mode: str = ""):
    from .scenario import with_cook_torrance_form
    from .simulate import simulate

    sc = _scenario(text, file, library_dirs, site_dirs)
    sc = replace(sc, measurement=replace(sc.measurement, r_percent=float(r_percent)))
    if cook_torrance:   # study [options] cook_torrance: the diffuse form of truth and filters
        sc = replace(sc, shape=with_cook_torrance_form(sc.shape, cook_torrance))
    if truth_acs_mode:  # study [options] truth_acs_mode: the controlled truth's ζ model
        sc = replace(sc, attitude=replace(sc.attitude, acs_mode=truth_acs_mode))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the thesis cases ignore the eclipse on purpose
        return simulate(sc, seed=sim_seed)


def task_lightcurve(task):
    """The simulated lightcurve of one :class:`~lightcurve.studies.study.RunTask` (its cell's
    noise level, the task's simulation seed and the study's truth options ``cook_torrance`` and
    ``truth_acs_mode``), cached per process: every filter and initial-error setting of a run
    index gets the same curve. Before any ``hide_glints_mag`` (that acts on the filters' view)."""
    opts = dict(task.options)
    return _lightcurve(task.scenario_text, task.scenario_file, float(task.cell.r_percent),
                       int(task.sim_seed), tuple(getattr(task, "library_dirs", ())),
                       tuple(getattr(task, "site_dirs", ())), opts.get("cook_torrance", ""),
                       opts.get("truth_acs_mode", ""))


#: half-width (epochs) of the running median that :func:`hide_glints` compares each epoch with
GLINT_HALF_WINDOW = 4


def glint_height(curve) -> np.ndarray:
    """Per epoch, how many magnitudes the noise-free magnitude (``truth_mag``) is brighter than
    the median of the noise-free magnitudes of the same site's epochs within
    ±:data:`GLINT_HALF_WINDOW` epochs of it (the window is shortened at the ends of a site's
    run; a local median, so that the slow brightening over a pass is not taken for a spike).
    Positive: brighter than its neighbourhood (mag). Needs a simulated curve (``truth_mag``)."""
    if curve.truth_mag is None:
        raise InputError("finding the glint epochs needs the noise-free magnitudes of a "
                         "simulated curve", field="truth_mag")
    m = np.asarray(curve.truth_mag, float)
    site = (np.zeros(len(m), int) if getattr(curve, "site", None) is None
            else np.asarray(curve.site).reshape(-1))
    height = np.zeros(len(m))
    h = GLINT_HALF_WINDOW
    pad = np.full(h, np.nan)     # NaN padding: nanmedian then shortens the end windows
    for s in np.unique(site):
        idx = np.flatnonzero(site == s)
        win = np.lib.stride_tricks.sliding_window_view(np.concatenate([pad, m[idx], pad]),
                                                       2 * h + 1)
        with warnings.catch_warnings():     # an all-NaN window gives NaN (no spike)
            warnings.simplefilter("ignore", RuntimeWarning)
            height[idx] = np.nanmedian(win, axis=1) - m[idx]
    return height


def hide_glints(curve, brighter_mag: float, after_s: float | None = None):
    """``curve`` without its specular spikes: the epochs whose :func:`glint_height` exceeds
    ``brighter_mag`` (mag) — with ``after_s``, only those later than ``after_s`` seconds after
    the curve's first epoch. Diagnostic of study options ``hide_glints_mag`` and
    ``hide_glints_after_s``: Bernard §9.4.5 states that the large spikes of the controlled
    fast-spinning curves are not present in the uncontrolled ones (Fig. 9.19), because the
    disturbance torques move the attitude off the ideal conditions over time, while the
    uncontrolled truth simulated here keeps them. Needs a simulated curve (``truth_mag``)."""
    hide = glint_height(curve) > float(brighter_mag)
    if after_s is not None:
        t = np.asarray(curve.t, float)
        hide &= t - t.min() > float(after_s)
    return curve.subset(~hide)


@functools.lru_cache(maxsize=32)
def _filter_eta(text: str, file: str, horizon_s: float, library_dirs: tuple = (),
                site_dirs: tuple = ()) -> float:
    """The filters' σ_η (deg/s^1.5) for study option ``filter_drift_horizon_s``: the scenario's
    ``drift_deg_per_orbit`` reached after ``horizon_s`` seconds instead of one orbit
    (:func:`lightcurve.studies.scenario.eta_sigma_from_drift`)."""
    from .scenario import eta_sigma_from_drift

    sc = _scenario(text, file, library_dirs, site_dirs)
    return eta_sigma_from_drift(sc.attitude.drift_deg_per_orbit, horizon_s)


#: study [options] passed to :func:`lightcurve.filters.invert` unchanged, for every filter
_INVERT_OPTIONS = ("acs_mode", "variant", "gate", "eta_sigma_deg_s2")


def execute_task(task: RunTask, device: str = "cpu") -> dict:
    """Run one task: simulate the cell's scenario with ``task.sim_seed``, invert with
    ``task.filter_seed``, compute :func:`~lightcurve.studies.metrics.run_metrics`.

    Never raises for a failing run: the result has ``status = "failed"`` and ``error`` (the
    traceback text). Simulated lightcurves are cached per process (the same lightcurve serves
    every filter and initial-error setting of a run index).

    Returns
    -------
    dict
        ``run_id``, ``cell`` (dict), ``run``, ``sim_seed``, ``filter_seed``, ``status``,
        ``error``, ``wall_s`` and, on success, ``metrics`` plus per-epoch arrays ``t`` (s),
        ``att_error_deg``, ``att_sigma_deg`` (N×3, deg, body axes), ``omega_error_rad_s``,
        ``omega_sigma_rad_s`` (N×3, rad/s).
    """
    from ..filters import invert

    c = task.cell
    try:  # compile / load the kernels once per process, so that runtime_s times the filter only
        from ..warmup import warm_up

        warm_up((c.filter,), dynamics=(c.dynamics,), reflection=c.reflection == "model3")
    except Exception:  # noqa: BLE001 - a failed warm-up only costs the timing
        pass
    t0 = time.perf_counter()
    res = {"run_id": task.run_id, "cell": c.as_dict(), "run": int(task.run),
           "sim_seed": int(task.sim_seed), "filter_seed": int(task.filter_seed),
           "status": "ok", "error": ""}
    try:
        opts = dict(task.options)
        lc = task_lightcurve(task)
        if "hide_glints_mag" in opts:
            lc = hide_glints(lc, float(opts["hide_glints_mag"]), opts.get("hide_glints_after_s"))
        kw = {}
        if c.filter == "bpf" and "particles" in opts:
            kw["particles"] = int(opts["particles"])
        if c.filter == "bpf" and device != "cpu":
            kw["device"] = device
        # [options] that are invert() keywords as they stand (validated by load_study);
        # eta_sigma_deg_s2 is the filters' η only: the simulated truth keeps the scenario's
        kw.update({k: opts[k] for k in _INVERT_OPTIONS if k in opts})
        if "filter_drift_horizon_s" in opts and c.dynamics == "uncontrolled":
            kw["eta_sigma_deg_s2"] = _filter_eta(
                task.scenario_text, task.scenario_file, float(opts["filter_drift_horizon_s"]),
                tuple(getattr(task, "library_dirs", ())), tuple(getattr(task, "site_dirs", ())))
        for k in ("alpha", "beta", "kappa"):
            if k in opts and c.filter == "ukf":
                kw[k] = float(opts[k])
        if task.init_seed is not None:
            kw["init_seed"] = int(task.init_seed)
        if c.reflection != "none":
            kw["reflection"] = c.reflection
        kw.update(dict(dict(opts.get("filters", ())).get(c.filter, ())))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            est = invert(lc, c.filter, seed=int(task.filter_seed),
                         sigma_theta_deg=float(c.sigma_theta_deg),
                         sigma_omega_deg_s=float(c.sigma_omega_deg_s), **kw)
        res["metrics"] = run_metrics(est)
        res["t"] = np.asarray(est.t, float)
        res["att_error_deg"] = np.asarray(est.att_error_deg, float)
        res["att_sigma_deg"] = np.asarray(est.att_sigma_deg, float)
        res["omega_error_rad_s"] = np.asarray(est.omega_error_rad_s, float)
        res["omega_sigma_rad_s"] = np.asarray(est.omega_sigma_rad_s, float)
    except Exception as exc:  # noqa: BLE001 - a failing run is recorded, the study goes on
        res["status"] = "failed"
        res["error"] = f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=8)}"
    res["wall_s"] = time.perf_counter() - t0
    return res


# ----------------------------------------------------------------------------------------
# run files
# ----------------------------------------------------------------------------------------
_ARRAYS = (("t", "s"), ("att_error_deg", "deg, body axes, rotation vector of q_true * q_est^-1"),
           ("att_sigma_deg", "deg, 1 sigma"), ("omega_error_rad_s", "rad/s, body axes"),
           ("omega_sigma_rad_s", "rad/s, 1 sigma"))


def write_run(out_dir, result: dict, study_hash: str) -> Path:
    """Store one run's result as ``DIR/runs/<run_id>.h5`` (atomic). Returns the path."""
    import h5py

    path = Path(out_dir) / "runs" / f"{result['run_id']}.h5"
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as h:
            h.attrs["format"] = RUN_FORMAT
            h.attrs["format_version"] = 1
            h.attrs["study_hash"] = study_hash
            h.attrs["cell_json"] = json.dumps(result["cell"])
            for k in ("run_id", "status", "error"):
                h.attrs[k] = str(result[k])
            for k in ("run", "sim_seed", "filter_seed"):
                h.attrs[k] = int(result[k])
            h.attrs["wall_s"] = float(result["wall_s"])
            if result["status"] == "ok":
                h.attrs["metrics_json"] = json.dumps(result["metrics"])
                for name, units in _ARRAYS:
                    d = h.create_dataset(name, data=np.asarray(result[name], float))
                    d.attrs["units"] = units
    return path


def run_record(result: dict) -> dict:
    """The part of :func:`read_run`'s dict that :func:`summarize` uses (status, error, wall
    time, metrics, ``t``, ``att_error_deg``) for the file :func:`write_run` makes of ``result``,
    built in memory with the same conversions (strings, the metrics through JSON, float
    arrays), so a summary of records equals a summary of the files."""
    out = {k: str(result[k]) for k in ("run_id", "status", "error")}
    out["wall_s"] = float(result["wall_s"])
    if out["status"] == "ok":
        out["metrics"] = json.loads(json.dumps(result["metrics"]))
        for name in ("t", "att_error_deg"):
            out[name] = np.array(result[name], dtype=float)
    return out


RECORDS_KEPT = 100_000
"""Runs of one :func:`run_study` call whose :func:`run_record` is kept for the summary (about
2.3 kB each for a 73-epoch run); later runs are read back from their files."""


def read_run(path) -> dict:
    """Read a run file written by :func:`write_run` (same keys as :func:`execute_task`)."""
    from ..io.safe_open import open_hdf5, read_dataset

    path = Path(path)
    with open_hdf5(path, track=False) as h:  # the study's own files, not inputs
        if h.attrs.get("format") != RUN_FORMAT:
            raise InputError("not a study run file", file=path, field="format",
                             value=h.attrs.get("format"), allowed=RUN_FORMAT)
        out = {k: str(h.attrs[k]) for k in ("run_id", "status", "error", "study_hash")}
        out.update({k: int(h.attrs[k]) for k in ("run", "sim_seed", "filter_seed")})
        out["wall_s"] = float(h.attrs["wall_s"])
        out["cell"] = json.loads(str(h.attrs["cell_json"]))
        if out["status"] == "ok":
            out["metrics"] = json.loads(str(h.attrs["metrics_json"]))
            for name, _ in _ARRAYS:
                out[name] = np.asarray(read_dataset(h, name, max_elements=10**9, file=path))
    return out


def read_outside_flags(out_dir, runs: int, cells=None) -> dict:
    """The outside-3σ flags of a study folder's finished runs 0…runs−1, per cell.

    Reads only the run files' attributes (:func:`write_run`), for summaries written before
    they carried ``color_probability``; ``cells`` (dicts with the GRID_KEYS) limits the reading
    to those cells' files. Returns ``{tuple of the cell's GRID_KEYS values: (R, 6) int array}``,
    runs in index order; failed runs and unreadable files are left out.
    """
    from ..io.safe_open import open_hdf5
    from .study import Cell

    per = {}
    d = Path(out_dir) / "runs"
    if not d.is_dir():
        files = []
    elif cells is None:
        files = sorted(d.glob("*.h5"))
    else:
        tags = {Cell(**{k: c[k] for k in GRID_KEYS}).tag for c in cells}
        files = sorted(p for p in d.glob("*.h5") if p.name.partition("_r")[0] in tags)
    for p in files:
        if p.name.startswith("."):
            continue
        try:
            with open_hdf5(p, track=False) as h:
                if h.attrs.get("format") != RUN_FORMAT or str(h.attrs["status"]) != "ok":
                    continue
                i = int(h.attrs["run"])
                if i >= runs:
                    continue
                cell = json.loads(str(h.attrs["cell_json"]))
                out = json.loads(str(h.attrs["metrics_json"]))["outside"]
        except (OSError, KeyError, ValueError):   # InputError included
            continue
        per.setdefault(tuple(cell.get(k) for k in GRID_KEYS), {})[i] = out
    return {k: np.asarray([v[i] for i in sorted(v)], int).reshape(-1, 6) for k, v in per.items()}


def finished_runs(out_dir) -> set:
    """Run ids with a stored file under ``DIR/runs`` (temporary files are ignored)."""
    d = Path(out_dir) / "runs"
    if not d.is_dir():
        return set()
    return {p.stem for p in d.glob("*.h5") if not p.name.startswith(".")}


def prepare_output(out_dir, study: Study, force: bool = False) -> None:
    """Create ``DIR`` and ``DIR/study.json``; refuse a different study unless ``force``.

    With ``force`` and a different stored study, the stored runs, summary and report are
    deleted first.
    """
    from .study import code_fingerprint

    out = Path(out_dir)
    meta = out / "study.json"
    h = study.hash
    fp = code_fingerprint()
    discard = False
    if meta.exists() or meta.is_symlink():
        olddoc = read_study_meta(meta)
        old = olddoc.get("study_hash")
        if old != h:
            if not force:
                # same inputs (study.json files written before the code fingerprint existed
                # store the input-only hash as study_hash) → the code changed
                if olddoc.get("input_hash", old) == study.input_hash:
                    raise InputError(
                        "the lightcurve code changed since the stored runs were made (package "
                        f"version {olddoc.get('package_version', '?')} -> "
                        f"{fp['package_version']}, source hash "
                        f"{str(olddoc.get('source_sha256', '?'))[:12]} -> "
                        f"{fp['source_sha256'][:12]}); new runs would not be comparable. Use "
                        "--force to discard the stored runs and rerun, or another -o",
                        file=study.source, field="study_hash", value=h[:16],
                        allowed=f"{str(old)[:16]} (stored in {meta})")
                raise InputError(
                    "the output folder holds runs of a different study (the study file or one "
                    "of its scenario files changed); use --force to discard them, or another -o",
                    file=study.source, field="study_hash", value=h[:16],
                    allowed=f"{str(old)[:16]} (stored in {meta})")
            discard = True
    open_runs_folder(out, discard)
    clean_stale_temp(out)
    if not meta.exists() or force:
        doc = {"format": "lightcurve-study", "format_version": 1, "study_hash": h,
               "input_hash": study.input_hash, "package_version": fp["package_version"],
               "source_sha256": fp["source_sha256"], "name": study.name, "seed": study.seed, "source": study.source,
               "study_toml": study.text, "cells": [c.as_dict() for c in study.cells]}
        atomic_write_text(meta, json.dumps(doc, indent=1) + "\n")


# ----------------------------------------------------------------------------------------
# executors: generators of results in completion order
# ----------------------------------------------------------------------------------------
def _iter_inline(tasks, fn=None):
    fn = execute_task if fn is None else fn
    for t in tasks:
        yield fn(t)


def init_worker(parent_pid: int, numba_threads: int | None = None) -> None:
    """Initialiser of every pool worker: die with the main process
    (:func:`lightcurve.process.watch_parent`), single-threaded BLAS
    (:func:`limit_blas_threads`), at most ``numba_threads`` numba threads
    (:mod:`lightcurve.threads`: workers × threads ≤ cores)."""
    from ..process import watch_parent
    from ..threads import limit_numba_threads

    watch_parent(parent_pid)
    limit_blas_threads()
    if numba_threads is not None:
        limit_numba_threads(numba_threads)


def process_pool(workers: int):
    """A ``ProcessPoolExecutor`` of ``workers`` processes whose workers die with this process
    (forkserver start method where available, else spawn; :func:`init_worker`). Stop it with
    :func:`lightcurve.process.stop_pool` when interrupted."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    from ..threads import threads_per_worker

    nt = threads_per_worker(workers)   # set in each worker by init_worker
    # forkserver, not fork: forking a process that already ran OpenMP (numba parallel
    # kernels, BLAS) aborts the child; the server starts clean and preloads the filters once
    if "forkserver" in mp.get_all_start_methods():
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(["lightcurve.studies.runner", "lightcurve.filters"])
    else:
        ctx = mp.get_context("spawn")
    return ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=init_worker,
                               initargs=(os.getpid(), nt))


def map_in_pool(fn, items, workers: int, progress=None, chunksize: int = 1) -> list:
    """``[fn(x) for x in items]`` in input order, in :func:`process_pool` workers when
    ``workers`` > 1 (stopped at once if interrupted), else in this process; ``progress``: a
    callable called with no argument after each result (a progress bar), or None."""
    out = []
    if workers <= 1:
        for x in items:
            out.append(fn(x))
            if progress is not None:
                progress()
        return out
    from ..process import stop_pool

    ex = process_pool(workers)
    try:
        for r in ex.map(fn, items, chunksize=chunksize):
            out.append(r)
            if progress is not None:
                progress()
    except BaseException:
        stop_pool(ex)
        raise
    ex.shutdown(wait=True)
    return out


class _ThreadLimited:
    """``fn(task)`` run with at most n numba threads in the calling thread (Dask tasks run in
    the worker's executor threads, where a limit set at worker start does not apply). ``n``
    comes from the cores of the worker's host and the Dask threads on it (``host_threads``:
    host → threads of all workers there; a worker not listed divides by its own threads)."""

    def __init__(self, fn, host_threads):
        self.fn = fn
        self.host_threads = dict(host_threads)

    def __call__(self, task):
        from ..threads import available_cores, limited_threads, user_thread_limit

        try:
            import distributed

            w = distributed.get_worker()
            host = str(w.address).split("://")[-1].rsplit(":", 1)[0]
            busy = self.host_threads.get(host) or int(w.state.nthreads)
        except (ImportError, ValueError, AttributeError):
            busy = 1
        n = max(1, available_cores() // max(1, int(busy)))
        u = user_thread_limit()
        with limited_threads(min(n, u) if u is not None else n):
            return self.fn(task)


def _iter_pool(tasks, workers, fn=None):
    from concurrent.futures import FIRST_COMPLETED, wait

    from ..process import stop_pool

    fn = execute_task if fn is None else fn
    ex = process_pool(workers)
    try:
        pending = set()
        it = iter(tasks)
        # bounded in-flight queue: tasks are taken from the (lazy) iterable as slots free up,
        # and the results come back as they complete
        for t in it:
            pending.add(ex.submit(fn, t))
            if len(pending) >= 4 * workers:
                break
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                yield f.result()
                nxt = next(it, None)
                if nxt is not None:
                    pending.add(ex.submit(fn, nxt))
    except BaseException:  # interrupted (signal, consumer gone, error): stop now, not later
        stop_pool(ex)
        raise
    ex.shutdown(wait=True)


def _import_distributed():
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise InputError("Dask executors need the 'distributed' extra: pip install "
                         "'lightcurve[distributed]'", field="executor",
                         value="--scheduler/--dask-local") from None
    return distributed


def _iter_dask(tasks, *, address=None, n_workers=None, fn=None, key=None):
    distributed = _import_distributed()
    fn = execute_task if fn is None else fn
    key = (lambda t: f"lightcurve-run-{t.run_id}-{t.filter_seed}") if key is None else key
    from ..threads import threads_per_worker

    cluster = None
    if address is None:
        import logging

        nt = threads_per_worker(int(n_workers))
        # The worker processes read their logging level from the environment when they import
        # distributed; silence_logs covers a worker only while it runs, not its teardown, whose
        # INFO/heartbeat lines would reach the user's stderr after a successful run. A level the
        # user set (DASK_LOGGING__DISTRIBUTED) is kept.
        with _environ_default(DASK_LOGGING__DISTRIBUTED="critical"):
            cluster = distributed.LocalCluster(n_workers=int(n_workers), threads_per_worker=1,
                                               processes=True, dashboard_address=":0",
                                               silence_logs=logging.ERROR,
                                               env={"NUMBA_NUM_THREADS": str(nt)})
        client = distributed.Client(cluster)
    else:
        try:
            client = distributed.Client(address, timeout=30)
        except (OSError, TimeoutError) as exc:
            raise InputError(f"cannot connect to the Dask scheduler: {exc}", field="--scheduler",
                             value=address) from None
    try:
        if cluster is not None:  # our own workers die with this process (watch_parent)
            from ._dask_plugin import ParentWatch

            client.register_plugin(ParentWatch(os.getpid()), name="lightcurve-parent-watch")
        try:
            window = max(64, 4 * sum(client.nthreads().values()))
        except Exception:  # noqa: BLE001 - a scheduler without workers yet
            window = 64
        hosts = {}
        for addr, info in client.scheduler_info().get("workers", {}).items():
            h = str(addr).split("://")[-1].rsplit(":", 1)[0]
            hosts[h] = hosts.get(h, 0) + int(info.get("nthreads", 1))
        fn = _ThreadLimited(fn, hosts)
        it = iter(tasks)
        ac = distributed.as_completed()
        # bounded in flight: tasks are generated lazily and submitted as results come back
        for t in itertools.islice(it, window):
            ac.add(client.submit(fn, t, key=key(t), pure=False))
        for fut in ac:
            res = fut.result()
            fut.release()
            nxt = next(it, None)
            if nxt is not None:
                ac.add(client.submit(fn, nxt, key=key(nxt), pure=False))
            yield res
    except BaseException:  # interrupted, consumer gone or a task failed: close at once
        if cluster is not None:
            _close_local_cluster(client, cluster, graceful=False)
        else:
            client.close()
        raise
    if cluster is not None:
        _close_local_cluster(client, cluster, graceful=True)
    else:
        client.close()


@contextlib.contextmanager
def _environ_default(**values):
    """Set environment variables that are not set yet, for the duration of the block (child
    processes started inside it inherit them); restore the environment afterwards."""
    added = [k for k in values if k not in os.environ]
    for k in added:
        os.environ[k] = values[k]
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


def _close_local_cluster(client, cluster, *, graceful: bool) -> None:
    """Shut our own LocalCluster down: after a complete run (``graceful``) the workers first,
    then the scheduler; after an interruption or a failure, everything at once.

    Closing the cluster directly stops the scheduler while its workers may still be sending a
    heartbeat; the worker then logs "Failed to communicate with scheduler during heartbeat" (an
    ERROR with a traceback on stderr) although every task succeeded. Retiring the workers while
    the scheduler still answers closes them cleanly; whatever fails here is teardown only."""
    import logging

    log = logging.getLogger("distributed")
    level = log.level
    log.setLevel(logging.CRITICAL)  # the closing connections' INFO lines are not news either
    try:
        try:
            if graceful:
                client.retire_workers(close_workers=True)
        except Exception:  # noqa: BLE001 - teardown after the results are in: never an error
            pass
        try:
            client.close()
        finally:
            cluster.close()
    finally:
        log.setLevel(level)



def iter_results(tasks, fn=None, *, workers: int | None = None, scheduler: str | None = None,
                 dask_local: int | None = None, key=None):
    """Run ``fn(task)`` for every task on the chosen executor; yield results as they complete.

    The executors of :func:`run_study`, shared with the batch inversion
    (:mod:`lightcurve.studies.batch`): an existing Dask cluster (``scheduler`` address), a Dask
    ``LocalCluster`` with ``dask_local`` worker processes, or a local process pool of
    ``workers`` processes (forkserver; default ``os.cpu_count()``; 1 runs inline, in this
    process). ``fn`` must be a module-level function (pickled by reference) and never raise
    for a failing task (return the failure instead); default :func:`execute_task`. ``key``
    maps a task to a unique Dask key (default: the study run id). At most one of
    ``workers``, ``scheduler``, ``dask_local``.
    """
    if sum(x is not None for x in (workers, scheduler, dask_local)) > 1:
        raise InputError("choose one executor: --workers, --scheduler or --dask-local",
                         field="executor")
    tasks = iter(tasks)  # consumed lazily by every executor
    first = next(tasks, None)
    if first is None:
        return iter(())
    tasks = itertools.chain([first], tasks)
    if scheduler is not None:
        return _iter_dask(tasks, address=scheduler, fn=fn, key=key)
    if dask_local is not None:
        return _iter_dask(tasks, n_workers=int(dask_local), fn=fn, key=key)
    w = int(workers or os.cpu_count() or 1)
    return _iter_inline(tasks, fn) if w == 1 else _iter_pool(tasks, w, fn)


def progress_bar(total: int, *, initial: int = 0, desc: str = "", progress: bool = True):
    """The tqdm bar of studies and batch inversions (stderr; runs done, rate, time left).

    Callers add the failure count with ``bar.set_postfix(failures=n)``.
    """
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, disable=not progress, unit="run", desc=desc,
                mininterval=0.5, dynamic_ncols=True)


# ----------------------------------------------------------------------------------------
def run_study(study: Study, out_dir, *, runs: int | None = None, workers: int | None = None,
              scheduler: str | None = None, dask_local: int | None = None, force: bool = False,
              progress: bool = True, write_report: bool = True, device: str = "cpu") -> dict:
    """Run (or resume) a study and write ``summary.json`` and ``report.html``.

    Parameters
    ----------
    study : Study — from :func:`lightcurve.studies.study.load_study`
    out_dir : path — output folder (module docstring)
    runs : int, optional — runs per cell (default the study's)
    workers : int, optional — process-pool size (default ``os.cpu_count()``; 1 runs inline)
    scheduler : str, optional — address of an existing Dask scheduler (``tcp://…``)
    dask_local : int, optional — start a Dask LocalCluster with this many worker processes
    force : bool — discard stored runs of a different study instead of refusing
    progress : bool — tqdm progress bar (runs done, failures, time left) on stderr
    device : {"cpu", "gpu"} — where the particle-filter cells run
        (:func:`lightcurve.filters.invert`, ``device``); the results of a cell do not depend
        on it beyond round-off

    Returns
    -------
    dict — the summary (as written to ``summary.json``)
    """
    if sum(x is not None for x in (workers, scheduler, dask_local)) > 1:
        raise InputError("choose one executor: --workers, --scheduler or --dask-local",
                         field="executor")
    n = study.runs if runs is None else int(runs)
    if n < 1:
        raise InputError("runs must be >= 1", field="runs", value=n, allowed=">= 1")
    from ..io.locks import folder_lock

    out = Path(out_dir)
    with folder_lock(out, what="study folder"):
        prepare_output(out, study, force=force)
        done = finished_runs(out)
        total = len(study.cells) * n
        tags = {c.tag for c in study.cells}
        n_done = 0  # stored runs that belong to this study and run count (RunTask.run_id)
        for r in done:
            tag, _, num = r.rpartition("_r")
            n_done += (tag in tags and num.isdigit() and num == f"{int(num):05d}"
                       and int(num) < n)
        # generated lazily (a million runs never sit in memory as task objects), in the
        # order that puts runs sharing a simulated lightcurve (same dynamics, sites, r and
        # run index: common random numbers) back to back for each worker's cache
        todo = (t for t in study.iter_tasks(n) if t.run_id not in done)
        limit_blas_threads()  # before any worker starts (inherited) and for inline runs
        failures = 0
        fresh = {}  # the runs of this call, kept for the summary (not read back from disk)
        if n_done < total:
            fn = execute_task if device == "cpu" else functools.partial(execute_task,
                                                                        device=device)
            it = iter_results(todo, fn, workers=workers, scheduler=scheduler,
                              dask_local=dask_local)
            bar = progress_bar(total, initial=n_done, desc=study.name, progress=progress)
            h = study.hash
            try:
                for res in it:
                    write_run(out, res, h)
                    if len(fresh) < RECORDS_KEPT:
                        fresh[res["run_id"]] = run_record(res)
                    if res["status"] != "ok":
                        failures += 1
                    bar.set_postfix(failures=failures, refresh=False)
                    bar.update(1)
            finally:
                close = getattr(it, "close", None)
                if close is not None:
                    close()  # stops the executor now (workers terminated if interrupted)
                bar.close()
        return summarize(study, out, runs=n, write_report=write_report, records=fresh)


def _code_fields() -> dict:
    from .study import code_fingerprint

    fp = code_fingerprint()
    return {"package_version": fp["package_version"], "source_sha256": fp["source_sha256"]}


def summarize(study: Study, out_dir, *, runs: int | None = None, write_report: bool = True,
              records: dict | None = None) -> dict:
    """Aggregate the stored runs into ``DIR/summary.json`` (and ``DIR/report.html``).

    Only the runs 0…runs−1 of each cell are used (a study extended and then summarised with
    fewer runs ignores the extra files). Cells keep the study's grid order. ``records`` maps
    run ids to :func:`run_record` of runs just written (their files are not read again).
    """
    from .agreement import agreement, thesis_color
    from .metrics import FULL_RUNS, rss_envelope

    out = Path(out_dir)
    n = study.runs if runs is None else int(runs)
    cells, groups = [], {}
    for c in study.cells:
        mets, fails, ts, rss, errors, walls = [], 0, [], [], [], []
        for i in range(n):
            rid = f"{c.tag}_r{i:05d}"
            r = records.get(rid) if records else None
            if r is None:
                p = out / "runs" / f"{rid}.h5"
                if not p.exists():
                    continue
                r = read_run(p)
            walls.append(r["wall_s"])
            if r["status"] != "ok":
                fails += 1
                errors.append(r["error"].splitlines()[0] if r["error"] else "")
                continue
            mets.append(r["metrics"])
            ts.append(r["t"])
            rss.append(np.linalg.norm(r["att_error_deg"], axis=1))
        entry = cell_summary(c.as_dict(), mets, fails)
        entry["missing"] = int(n - len(mets) - fails)
        entry["thesis_color"] = thesis_color(study.thesis_table, c.as_dict())
        if errors:
            entry["first_error"] = errors[0]
        cells.append(entry)
        # envelopes pool the runs of every σω and r: one curve per (filter, dynamics, sites, σθ)
        gk = (c.filter, c.dynamics, c.sites, c.sigma_theta_deg, c.reflection)
        g = groups.setdefault(gk, ({"filter": c.filter, "dynamics": c.dynamics, "sites": c.sites,
                                    "sigma_theta_deg": c.sigma_theta_deg,
                                    "reflection": c.reflection}, [], []))
        g[1].extend(ts)
        g[2].extend(rss)
    envelopes = [(g[0], rss_envelope(g[1], g[2])) for g in groups.values()]
    summary = {"format": _SUMMARY_FORMAT, "format_version": 1, "study": study.name,
               "study_hash": study.hash, **_code_fields(), "seed": study.seed,
               "runs_per_cell": n,
               # the traffic-light rule is defined for 100 runs; fewer runs scale it
               # (lightcurve.studies.metrics.traffic_light) and the table is indicative
               "indicative": bool(n < FULL_RUNS),
               "variant": study.options.get("variant", "robust"),
               "grid_keys": list(GRID_KEYS), "cells": cells}
    if study.thesis_table is not None:
        summary["thesis_figure"] = study.thesis_table.figure
        summary["thesis_title"] = study.thesis_table.title
        summary["agreement"] = agreement(cells)
        summary["not_run_grey"] = [c.as_dict() for c in study.skipped_cells]
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1) + "\n")
    if write_report:
        from ..report.html import write_study_report

        write_study_report(out / "report.html", summary, envelopes)
    return summary

