"""CSS Monte Carlo studies (O'Keefe 2015 ch. 3): run, resume, summarise, report.

A study TOML (``pipelines/css/okeefe2015/*.toml``)::

    [study]
    name = "okeefe2015-fig3_09"
    experiment = "fig3_09"            # key of okeefe2015.THESIS_RESULTS (reference numbers)
    runs = 1000
    seed = 1
    settle_s = 300.0                  # sunlit time ignored at the start of the p99 level
    [scenario]
    configuration = "dual_pyramid"    # or "cube"
    controlled = false
    estimators = ["ekf", "eckf", "wavg", "lsmn", "wlsmn"]
    variants = ["thesis", "robust"]
    gyros = ["intermediate"]          # Table 2.3 grades or "none"
    duration_s = 6000.0
    albedo = "toms"                   # "toms" (1°×1.25° with its spread), "toms5", "builtin", "none"
    [simulation]                      # optional overrides of the §2.4 values (okeefe2015.py)
    [thesis_filter]                   # optional, for measured ablations: overrides of the thesis
    sigma_valpha = 0.2                # sun-line EKF/ECKF parameters (sunline_thesis.THESIS_PRM
                                      # names, SI units) in both thesis filters
    [robust_filter]                   # optional, likewise for the robust sun-line filters
    fov_model = false                 # (sunline_ekf.FilterParams fields)
    [gyroless]                        # optional, for measured ablations: the thesis variant's
    lowpass_hz = 0.1                  # §3.3.3 gyro-less rate processing (okeefe2015.GYROLESS
                                      # names: rate_limit_deg_s, lowpass_hz, sigma_s)

Every case (estimator × variant × gyro) flies the same dispersed spacecraft for run ``i``
(seed ``[seed, i]``, common random numbers; :func:`lightcurve.css.truth.simulate_css_cases`).
One task per run and gyro (uncontrolled: the truth is shared by all estimators) or per run,
gyro, estimator and variant (controlled).  Tasks run on the executors of
:func:`lightcurve.studies.runner.iter_results` (process pool, Dask); each finished task is
stored as ``DIR/runs/<task>.npz`` (atomic) and a restarted study skips it.

Metrics (angles deg, times s), on the thesis's time axis — "the time spent in the shadow of the
Earth has been removed" (§3.3.1): τ = the time with at least one sensor directly lit:

* error envelopes over runs (p50/p90/p99 and mean) against τ;
* ``p99_level_deg``: the median over τ ≥ ``settle_s`` of the p99 envelope (the level the thesis
  quotes, "reducing the ... error to 1.75° within a few minutes and maintaining that level");
  ``p99_pooled_deg``: p99 of every sample with τ ≥ settle_s;
* time with the error above 15° and 30° per orbit (per run; median, p99 and largest), and with
  control the same for the pointing error of the +z axis;
* the sun-line filters' direction NEES (2 degrees of freedom; ideal mean 2): each run's mean
  over the settled samples, then the mean over runs (``nees_mean``) and the median run
  (``nees_run_median``, which the few runs that lose the Sun cannot move).
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path, atomic_write_text
from ..io.study_folder import open_runs_folder, read_study_meta
from ..io.tomlio import Section, load_toml
from . import okeefe2015 as ok
from ..core.constants import MU_EARTH, R_EARTH_M
from .truth import ESTIMATORS

__all__ = ["StudySpec", "load_css_study", "study_tasks", "run_task", "run_css_study",
           "summarize_css_study", "write_css_report", "settled_mask", "direction_nees",
           "TAU_STEP_S", "ERR_BINS", "envelope_level"]

TAU_STEP_S = 10.0
"""Resolution of the stored envelopes on the sunlit-time axis, s."""
ERR_BINS = np.concatenate([np.arange(0.0, 20.0, 0.02), np.arange(20.0, 180.5, 0.5)])
"""Histogram bins of the pooled error (deg)."""
_GYROS = tuple(ok.GYRO_TABLE_2_3) + ("rate", "tactical", "navigation", "none")
_ALBEDO = ("toms", "toms5", "toms10", "builtin", "none")   # TOMS names: experiments.TOMS_ALBEDO_GRIDS


def direction_nees(d_hat, P, s_true):
    """Normalised estimation error squared of the Sun *direction* (2 degrees of freedom).

    The sun-line state ``d`` carries an unknown scale, so only its direction is compared:
    with ``ŝ = d/|d|`` and an orthonormal basis ``B`` (3×2) of the plane perpendicular to
    ``ŝ``, ``e = |d| Bᵀ s_true`` and ``NEES = eᵀ (Bᵀ P B)⁻¹ e`` (χ² with 2 degrees of freedom
    for a consistent filter: mean 2, 95 % below 5.991).  d_hat (K,3), P (K,3,3), s_true (K,3)
    unit; returns (K,) (NaN where d is zero).
    """
    d = np.atleast_2d(np.asarray(d_hat, dtype=float))
    P = np.asarray(P, dtype=float).reshape(-1, 3, 3)
    s = np.atleast_2d(np.asarray(s_true, dtype=float))
    nd = np.linalg.norm(d, axis=1)
    ok_ = nd > 0
    u = np.where(ok_[:, None], d / np.where(ok_, nd, 1.0)[:, None], [1.0, 0.0, 0.0])
    a = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    b2 = a - np.sum(a * u, axis=1, keepdims=True) * u
    b2 /= np.linalg.norm(b2, axis=1, keepdims=True)
    b3 = np.cross(u, b2)
    B = np.stack([b2, b3], axis=2)
    e = nd[:, None] * np.einsum("kij,ki->kj", B, s)
    P2 = np.einsum("kia,kij,kjb->kab", B, P, B)
    det = P2[:, 0, 0] * P2[:, 1, 1] - P2[:, 0, 1] * P2[:, 1, 0]
    good = ok_ & (det > 0)
    det = np.where(good, det, 1.0)
    q = (P2[:, 1, 1] * e[:, 0] ** 2 - 2 * P2[:, 0, 1] * e[:, 0] * e[:, 1]
         + P2[:, 0, 0] * e[:, 1] ** 2) / det
    return np.where(good, q, np.nan)


def settled_mask(t, lit, settle_s):
    """Samples that are sunlit (lit > 0.999) and at least ``settle_s`` seconds after the
    latest entry into sunlight (or the start)."""
    t = np.asarray(t)
    sun = np.asarray(lit) > 0.999
    last_entry = np.empty_like(t)
    entry = t[0]
    for k in range(t.size):
        if sun[k] and (k == 0 or not sun[k - 1]):
            entry = t[k]
        last_entry[k] = entry
    return sun & (t - last_entry >= settle_s)


@dataclass
class StudySpec:
    """A study definition (module docstring)."""

    name: str = "css-study"
    experiment: str = ""
    runs: int = 100
    seed: int = 1
    settle_s: float = 300.0
    configuration: str = "dual_pyramid"
    controlled: bool = False
    estimators: tuple = ("ekf", "eckf", "wavg", "lsmn", "wlsmn")
    variants: tuple = ("thesis", "robust")
    gyros: tuple = ("intermediate",)
    duration_s: float = 6000.0
    albedo: str = "toms"
    thresholds_deg: tuple = (15.0, 30.0)
    simulation: dict = field(default_factory=dict)
    thesis_filter: dict = field(default_factory=dict)
    robust_filter: dict = field(default_factory=dict)
    gyroless: dict = field(default_factory=dict)
    text: str = ""
    source: str = ""

    @property
    def hash(self) -> str:
        d = asdict(self)
        d.pop("runs")
        d.pop("text")
        d.pop("source")
        for k in ("thesis_filter", "robust_filter", "gyroless"):
            if not d[k]:                # no override: the hash of a study without the section
                d.pop(k)
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()

    def cases(self):
        """(estimator, variant, gyro) of every case, in report order."""
        return [(e, v, g) for g in self.gyros for v in self.variants for e in self.estimators]


def scenario_for(spec: StudySpec, estimator, variant, gyro):
    """The :class:`~lightcurve.css.truth.CSSScenario` of one case."""
    from .experiments import TOMS_ALBEDO_GRIDS, thesis_albedo, thesis_scenario

    alb = spec.albedo
    if alb in TOMS_ALBEDO_GRIDS:
        alb = thesis_albedo(TOMS_ALBEDO_GRIDS[alb], required=True)
    sc = thesis_scenario(spec.configuration, estimator, variant=variant,
                         gyro=None if gyro == "none" else gyro, controlled=spec.controlled,
                         duration_s=spec.duration_s, albedo=alb, sim=dict(spec.simulation))
    if spec.thesis_filter and variant == "thesis" and sc.thesis_params is not None:
        from .sunline_thesis import THESIS_PRM

        p = np.array(sc.thesis_params, dtype=float)
        for k, v in spec.thesis_filter.items():
            p[THESIS_PRM.index(k)] = float(v)
        sc.thesis_params = p
    if spec.robust_filter and variant == "robust":
        sc.filter_params = replace(sc.filter_params, **spec.robust_filter)
    if spec.gyroless and variant == "thesis":
        sc.gyroless = {**sc.gyroless, **spec.gyroless}
    return sc


@dataclass(frozen=True)
class Task:
    """One unit of work: run ``run`` of the cases ``cases`` ((estimator, variant, gyro))."""

    task_id: str
    run: int
    cases: tuple
    spec_json: str


def study_tasks(spec: StudySpec, runs: int | None = None) -> list[Task]:
    """The tasks of a study (module docstring)."""
    n = spec.runs if runs is None else int(runs)
    sj = json.dumps(asdict(spec), default=str)
    tasks = []
    for i in range(n):
        for g in spec.gyros:
            if spec.controlled:
                for v in spec.variants:
                    for e in spec.estimators:
                        tasks.append(Task(f"r{i:05d}_{g}_{v}_{e}", i, ((e, v, g),), sj))
            else:
                cs = tuple((e, v, g) for v in spec.variants for e in spec.estimators)
                tasks.append(Task(f"r{i:05d}_{g}", i, cs, sj))
    return tasks


def _orbit_period(alt_m):
    a = R_EARTH_M + alt_m
    return 2 * np.pi * np.sqrt(a ** 3 / MU_EARTH)


def _case_key(c):
    return f"{c[0]}|{c[1]}|{c[2]}"


def _run_metrics(spec: StudySpec, r, period_s):
    """Per-run arrays and scalars stored in the task file."""
    dt = float(r.t[1] - r.t[0])
    direct = r.direct > 0
    tau = np.cumsum(direct) * dt
    grid = np.arange(0.0, spec.duration_s + TAU_STEP_S, TAU_STEP_S)
    idx = np.searchsorted(tau, grid, side="left")
    env = np.full(grid.size, np.nan, dtype=np.float32)
    okk = idx < tau.size
    env[okk] = r.error_deg[idx[okk]]
    env[grid > tau[-1]] = np.nan
    sel = direct & (tau >= spec.settle_s)
    hist = np.histogram(np.clip(r.error_deg[sel], 0, 180), ERR_BINS)[0].astype(np.int32)
    orbits = spec.duration_s / period_s
    out = {"env": env, "hist": hist,
           "sunlit_s": float(direct.sum() * dt)}
    for th in spec.thresholds_deg:
        out[f"above{th:g}"] = float(np.sum(direct & (r.error_deg > th)) * dt / orbits)
    if r.d_hat is not None:
        nees = direction_nees(r.d_hat[sel], r.p_cov[sel], r.s_true[sel])
        nees = nees[np.isfinite(nees)]
        out["nees_mean"] = float(np.mean(nees)) if nees.size else float("nan")
    if spec.controlled:
        axis = np.asarray(ok.CONTROL["axis"], float)
        pe = np.degrees(np.arccos(np.clip(r.s_true @ axis, -1, 1)))
        penv = np.full(grid.size, np.nan, dtype=np.float32)
        penv[okk] = pe[idx[okk]]
        penv[grid > tau[-1]] = np.nan
        out["pointing_env"] = penv
        for th in spec.thresholds_deg:
            out[f"pointing_above{th:g}"] = float(np.sum(direct & (pe > th)) * dt / orbits)
    return out


def _interruption(exc):
    """The KeyboardInterrupt (Ctrl-C, or :class:`lightcurve.process.Terminated` for SIGTERM/
    SIGHUP) behind ``exc``, or None.  A signal handler that raises while a numba kernel runs
    surfaces as ``SystemError: ... returned a result with an exception set`` with the
    interruption as its cause."""
    seen = set()
    e = exc
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return e
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return None


def run_task(task: Task) -> dict:
    """Execute one task (module-level, picklable; never raises: failures are returned)."""
    import time
    import traceback

    from .truth import simulate_css_cases

    t0 = time.perf_counter()
    d = json.loads(task.spec_json)
    for k in ("estimators", "variants", "gyros", "thresholds_deg"):
        d[k] = tuple(d[k])
    spec = StudySpec(**d)
    res = {"task_id": task.task_id, "run": task.run, "status": "ok", "error": "", "cases": {}}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scs = [scenario_for(spec, *c) for c in task.cases]
            rs = simulate_css_cases(scs, [spec.seed, task.run])
        period = _orbit_period(scs[0].altitude_m)
        for c, r in zip(task.cases, rs):
            res["cases"][_case_key(c)] = _run_metrics(spec, r, period)
    except Exception as exc:  # noqa: BLE001 - a failing run is recorded, the study goes on
        intr = _interruption(exc)
        if intr is not None:     # a signal that arrived inside a numba kernel: stop, record nothing
            raise intr from None
        res["status"] = "failed"
        res["error"] = f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=6)}"
    res["wall_s"] = time.perf_counter() - t0
    return res


def _write_task(out: Path, res: dict):
    arrays = {"meta": np.frombuffer(json.dumps(
        {"task_id": res["task_id"], "run": res["run"], "status": res["status"],
         "error": res["error"], "wall_s": res["wall_s"],
         "scalars": {k: {n: v for n, v in m.items() if np.isscalar(v)}
                     for k, m in res["cases"].items()}}).encode(), dtype=np.uint8)}
    for k, m in res["cases"].items():
        for n, v in m.items():
            if not np.isscalar(v):
                arrays[f"{k}::{n}"] = v
    path = out / "runs" / f"{res['task_id']}.npz"
    with atomic_path(path, suffix=".npz") as tmp:  # the temporary name ends in .npz
        np.savez_compressed(tmp, **arrays)


def _read_task(path: Path) -> dict:
    from ..io.safe_open import open_regular

    # the study's own run file, but in a user-chosen folder: a regular file, size-capped;
    # NumPy arrays only (no pickle)
    with open_regular(path, max_bytes=1 << 30, what="run file", track=False) as fh, \
            np.load(fh, allow_pickle=False) as z:
        meta = json.loads(bytes(z["meta"]).decode())
        cases = {k: dict(v) for k, v in meta["scalars"].items()}
        for name in z.files:
            if "::" in name:
                k, n = name.split("::", 1)
                cases.setdefault(k, {})[n] = z[name]
    meta["cases"] = cases
    return meta


def _prepare(out: Path, spec: StudySpec, force: bool):
    meta = out / "study.json"
    discard = False
    if meta.exists() or meta.is_symlink():
        old = read_study_meta(meta).get("study_hash")
        if old != spec.hash:
            if not force:
                raise InputError("the output folder holds runs of a different study; use "
                                 "--force to discard them, or another -o", file=spec.source,
                                 field="study_hash", value=spec.hash[:16],
                                 allowed=f"{str(old)[:16]} (stored in {meta})")
            discard = True
    open_runs_folder(out, discard)
    atomic_write_text(meta, json.dumps({"format": "lightcurve-css-study", "format_version": 1,
                                        "study_hash": spec.hash, "name": spec.name,
                                        "study_toml": spec.text, "source": spec.source},
                                       indent=1) + "\n")


def run_css_study(spec: StudySpec, out_dir, *, runs=None, workers=None, scheduler=None,
              dask_local=None, force=False, progress=True) -> dict:
    """Run (or resume) a study into ``out_dir`` and write ``summary.json`` and
    ``report.html``; returns the summary.  Executors as :func:`lightcurve.studies.runner.
    iter_results` (``workers`` default: the number of cores). The folder is locked while
    the study runs (:mod:`lightcurve.io.locks`)."""
    from ..io.locks import folder_lock

    out = Path(out_dir)
    n = spec.runs if runs is None else int(runs)
    if n < 1:
        raise InputError("runs must be >= 1", field="runs", value=n, allowed=">= 1")
    with folder_lock(out, what="study folder"):
        return _run_locked(spec, out, n, workers, scheduler, dask_local, force, progress)


def _run_locked(spec, out, n, workers, scheduler, dask_local, force, progress) -> dict:
    """:func:`run_css_study` while holding the folder's lock."""
    from ..studies.runner import iter_results, limit_blas_threads, progress_bar

    _prepare(out, spec, force)
    tasks = study_tasks(spec, n)
    done = {p.stem for p in (out / "runs").glob("*.npz")}
    todo = [t for t in tasks if t.task_id not in done]
    limit_blas_threads()
    if todo:
        w = workers
        if w is None and scheduler is None and dask_local is None:
            w = os.cpu_count() or 1
        bar = progress_bar(len(tasks), initial=len(tasks) - len(todo), desc=spec.name,
                           progress=progress)
        fails = 0
        try:
            for res in iter_results(todo, run_task, workers=w, scheduler=scheduler,
                                    dask_local=dask_local,
                                    key=lambda t: f"css-{spec.hash[:12]}-{t.task_id}"):
                _write_task(out, res)
                fails += res["status"] != "ok"
                bar.set_postfix(failures=fails, refresh=False)
                bar.update(1)
        finally:
            bar.close()
    summary = summarize_css_study(spec, out, runs=n)
    write_css_report(spec, summary, out)
    return summary


def _pct_from_hist(h, q):
    c = np.cumsum(h)
    if c[-1] == 0:
        return float("nan")
    k = np.searchsorted(c, q / 100.0 * c[-1])
    return float(ERR_BINS[min(k + 1, ERR_BINS.size - 1)])


def envelope_level(E, settle, q=99):
    """Percentile envelopes over runs of the errors ``E`` (runs × sunlit-time grid, deg; NaN
    where a run has no sample) and the reported level: the median over the grid points past
    the settling time (boolean ``settle``) that half the runs or more reach of the ``q``-th
    percentile envelope.  Returns (envelopes {"50", "90", "99", "mean"}, fraction of runs
    present per grid point, level or None)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        envs = {str(p): np.nanpercentile(E, p, axis=0) for p in sorted({50, 90, 99, q})}
        envs["mean"] = np.nanmean(E, axis=0)
        frac = np.mean(np.isfinite(E), axis=0)
        lv = envs[str(q)][settle & (frac >= 0.5)]
        level = float(np.nanmedian(lv)) if np.any(np.isfinite(lv)) else None
    return envs, frac, level


def summarize_css_study(spec: StudySpec, out_dir, *, runs=None) -> dict:
    """Aggregate the stored runs into ``summary.json`` (and return it)."""
    out = Path(out_dir)
    n = spec.runs if runs is None else int(runs)
    grid = np.arange(0.0, spec.duration_s + TAU_STEP_S, TAU_STEP_S)
    acc = {_case_key(c): {"env": [], "penv": [], "hist": np.zeros(ERR_BINS.size - 1, np.int64),
                          "sc": []} for c in spec.cases()}
    failures, first_error = 0, ""
    for t in study_tasks(spec, n):
        p = out / "runs" / f"{t.task_id}.npz"
        if not p.exists():
            continue
        r = _read_task(p)
        if r["status"] != "ok":
            failures += 1
            first_error = first_error or r["error"].splitlines()[0]
            continue
        for k, m in r["cases"].items():
            if k not in acc:
                continue
            a = acc[k]
            a["env"].append(m["env"])
            if "pointing_env" in m:
                a["penv"].append(m["pointing_env"])
            a["hist"] += m["hist"]
            a["sc"].append({x: v for x, v in m.items() if np.isscalar(v)})
    ref = ok.THESIS_RESULTS.get(spec.experiment, {})
    cases = []
    envelopes = {}
    settle = grid >= spec.settle_s
    for (e, v, g) in spec.cases():
        k = _case_key((e, v, g))
        a = acc[k]
        entry = {"estimator": e, "variant": v, "gyro": g, "runs": len(a["env"])}
        if a["env"]:
            E = np.vstack(a["env"]).astype(float)
            envs, frac, entry["p99_level_deg"] = envelope_level(E, settle)
            entry["p99_pooled_deg"] = _pct_from_hist(a["hist"], 99)
            entry["p50_pooled_deg"] = _pct_from_hist(a["hist"], 50)
            sc = a["sc"]
            for th in spec.thresholds_deg:
                vals = np.array([s[f"above{th:g}"] for s in sc])
                entry[f"above{th:g}_s_per_orbit"] = {
                    "median": float(np.median(vals)), "p99": float(np.percentile(vals, 99)),
                    "max": float(np.max(vals))}
                if spec.controlled:
                    pv = np.array([s[f"pointing_above{th:g}"] for s in sc])
                    entry[f"pointing_above{th:g}_s_per_orbit"] = {
                        "median": float(np.median(pv)), "p99": float(np.percentile(pv, 99)),
                        "max": float(np.max(pv))}
            nm = [s["nees_mean"] for s in sc if "nees_mean" in s and np.isfinite(s["nees_mean"])]
            if nm:
                entry["nees_mean"] = float(np.mean(nm))
                # a few runs that lose the Sun dominate the mean; the median run does not
                entry["nees_run_median"] = float(np.median(nm))
            envelopes[k] = {q: envs[q].tolist() for q in envs}
            envelopes[k]["fraction"] = frac.tolist()
            if a["penv"]:
                P = np.vstack(a["penv"]).astype(float)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    envelopes[k]["pointing99"] = np.nanpercentile(P, 99, axis=0).tolist()
        th_p99 = ref.get("p99_deg", {}).get(e)
        entry["thesis_p99_deg"] = th_p99
        if th_p99 is not None:
            entry["thesis_p99_bound"] = ok.thesis_p99_bound(spec.experiment, e)
        if (th_p99 is not None and entry.get("p99_level_deg") is not None
                and entry["thesis_p99_bound"] is None):
            entry["ratio_to_thesis"] = entry["p99_level_deg"] / th_p99
        th15 = ref.get("above15_min_per_orbit", {}).get(e)
        if th15 is not None:
            entry["thesis_above15_min_per_orbit"] = th15
        cases.append(entry)
    summary = {"format": "lightcurve-css-study-summary", "format_version": 1,
               "study": spec.name, "experiment": spec.experiment, "study_hash": spec.hash,
               "runs": n, "failures": failures, "first_error": first_error,
               "configuration": spec.configuration, "controlled": spec.controlled,
               "albedo": spec.albedo, "settle_s": spec.settle_s,
               "simulation": dict(spec.simulation), "thesis_filter": dict(spec.thesis_filter),
               "robust_filter": dict(spec.robust_filter), "gyroless": dict(spec.gyroless),
               "tau_step_s": TAU_STEP_S,
               "cases": cases, "open_choices": ok.OPEN_CHOICES,
               "verdict": _verdict(spec, cases)}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1, default=float) + "\n")
    atomic_write_text(out / "envelopes.json", json.dumps(envelopes) + "\n")
    return summary


def _verdict(spec, cases) -> dict:
    """One line, ``{"level", "text"}``: thesis-variant p99 levels against the thesis's numbers
    (:func:`lightcurve.css.okeefe2015.thesis_p99_agrees`: ±25 % of a level, or the side of a
    bound); ok when all agree, warn otherwise."""
    parts = []
    all_ok = True
    for c in cases:
        if c["variant"] != "thesis" or c.get("thesis_p99_deg") is None:
            continue
        lv = c.get("p99_level_deg")
        if lv is None:
            continue
        th = c["thesis_p99_deg"]
        bound = ok.thesis_p99_bound(spec.experiment, c["estimator"])
        agree = ok.thesis_p99_agrees(spec.experiment, c["estimator"], lv)
        if bound == "lower":
            parts.append(f"{c['estimator'].upper()} {lv:.1f}° ({'>' if agree else '≤'} {th:g}°)")
        elif bound == "upper":
            parts.append(f"{c['estimator'].upper()} {lv:.2f}° ({'≤' if agree else '>'} {th:g}°, "
                         "the thesis's bound)")
        else:
            parts.append(f"{c['estimator'].upper()} {lv:.2f}° vs {th:g}° "
                         f"({'within' if agree else 'outside'} ±25 %)")
        all_ok &= bool(agree)
    if not parts:
        return {"level": "warn", "text": "no thesis reference number for this experiment"}
    return {"level": "ok" if all_ok else "warn",
            "text": "thesis variant vs the thesis's 99th percentile: " + "; ".join(parts)}


def write_css_report(spec: StudySpec, summary: dict, out_dir) -> Path:
    """Self-contained ``report.html``: verdict, table (thesis variant, robust variant and the
    thesis's number side by side), percentile envelopes against sunlit time, time above
    15°/30° per orbit."""
    import html

    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from ..report.html import figure_to_data_uri

    out = Path(out_dir)
    from ..io.safe_open import read_json

    envs = read_json(out / "envelopes.json", what="envelopes.json", track=False)
    grid = np.arange(0.0, spec.duration_s + TAU_STEP_S, TAU_STEP_S) / 60.0
    rows = []
    for c in summary["cases"]:
        a15 = c.get("above15_s_per_orbit", {})
        p15 = c.get("pointing_above15_s_per_orbit", {})
        rows.append(
            "<tr>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in (
                c["estimator"].upper(), c["variant"], c["gyro"], c["runs"],
                _f(c.get("p99_level_deg")), _f(c.get("p99_pooled_deg")),
                _f(c.get("thesis_p99_deg")), _f(c.get("ratio_to_thesis")),
                _f(a15.get("median", None) and a15["median"] / 60),
                _f(a15.get("max", None) and a15["max"] / 60),
                _f(p15.get("max", None) and p15["max"] / 60),
                _f(c.get("thesis_above15_min_per_orbit")),
                f"{_f(c.get('nees_mean'))} / {_f(c.get('nees_run_median'))}")) + "</tr>")
    head = ("estimator", "variant", "gyro", "runs", "p99 level (deg)", "p99 pooled (deg)",
            "thesis p99 (deg)", "ratio", "min/orbit >15° median", "min/orbit >15° max",
            "pointing min/orbit >15° max", "thesis min/orbit >15°",
            "NEES mean / median run (ideal 2)")
    figs = []
    for gyro in spec.gyros:
        fig, axes = plt.subplots(1, len(spec.variants), figsize=(6.2 * len(spec.variants), 3.8),
                                 squeeze=False, sharey=True)
        for ax, v in zip(axes[0], spec.variants):
            for i, e in enumerate(spec.estimators):
                k = _case_key((e, v, gyro))
                if k not in envs:
                    continue
                p99 = np.asarray(envs[k]["99"], float)
                p50 = np.asarray(envs[k]["50"], float)
                ax.semilogy(grid, p99, color=f"C{i}", lw=1.4, label=f"{e.upper()} p99")
                ax.semilogy(grid, p50, color=f"C{i}", lw=0.8, ls="--")
            for th in spec.thresholds_deg:
                ax.axhline(th, color="k", lw=0.5, ls=":")
            ax.set_title(f"{v} variant, gyro {gyro} (solid p99, dashed median)", fontsize=9)
            ax.set_xlabel("time in sunlight (min)")
            ax.set_ylim(0.1, 180)
            ax.grid(True, which="both", alpha=0.3)
        axes[0, 0].set_ylabel("Sun-direction error (deg)")
        axes[0, 0].legend(fontsize=7, loc="upper right")
        figs.append((f"Error envelopes, gyro {gyro}", figure_to_data_uri(fig)))
    parts = [f"<p>{summary['runs']} runs per case, {summary['failures']} failed; configuration "
             f"{html.escape(spec.configuration)}, {'controlled' if spec.controlled else 'tumbling'}, "
             f"truth albedo {html.escape(spec.albedo)}; time axis: time with at least one "
             f"directly lit sensor (O'Keefe §3.3.1); p99 level: median of the p99 envelope "
             f"after {spec.settle_s:g} s of sunlit time.</p>",
             "<table><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>",
             *rows, "</table>"]
    for title, uri in figs:
        parts.append(f"<h2>{html.escape(title)}</h2><img src='{uri}' alt='{html.escape(title)}'>")
    parts.append("<h2>Values the text leaves open (our choices)</h2><ul>")
    parts += [f"<li><b>{html.escape(k)}</b>: {html.escape(v)}</li>"
              for k, v in ok.OPEN_CHOICES.items()]
    parts.append("</ul>")
    from ..report.style import page_html

    v = summary["verdict"]
    atomic_write_text(out / "report.html",
                      page_html(spec.name, (v["level"], v["text"]), "\n".join(parts)))
    return out


def _f(x):
    if x is None:
        return "–"
    if isinstance(x, float) and not np.isfinite(x):
        return "–"
    return f"{x:.3g}" if isinstance(x, float) else str(x)


def load_css_study(path) -> StudySpec:
    """Read a study TOML (module docstring); :class:`InputError` on bad input."""
    from ..filters.config import VARIANTS   # here: importing lightcurve.filters costs ~0.5 s

    path = Path(path)
    raw, text = load_toml(path, with_text=True)
    doc = Section(raw, file=path)
    st = doc.section("study")
    sc = doc.section("scenario")
    spec = StudySpec(
        name=st.str("name", "css-study"), experiment=st.str("experiment", ""),
        runs=st.int("runs", 100, min=1, max=100000), seed=st.int("seed", 1, min=0, max=2**63 - 1),
        settle_s=st.float("settle_s", 300.0, min=0.0))
    st.check_unknown()
    if spec.experiment and spec.experiment not in ok.THESIS_RESULTS:
        raise InputError("unknown experiment", file=path, field="study.experiment",
                         value=spec.experiment, allowed=", ".join(ok.THESIS_RESULTS))
    conf = sc.str("configuration", "dual_pyramid")
    if conf not in ("dual_pyramid", "cube"):
        raise InputError("unknown configuration", file=path, field="scenario.configuration",
                         value=conf, allowed="dual_pyramid, cube")

    def _list(key, default, allowed):
        v = sc.raw(key, list(default))
        if not isinstance(v, list) or not v or any(x not in allowed for x in v):
            raise InputError(f"bad {key} list", file=path, field=f"scenario.{key}", value=v,
                             allowed=", ".join(allowed))
        return tuple(v)

    alb = sc.str("albedo", "toms")
    if alb not in _ALBEDO:
        raise InputError("unknown albedo", file=path, field="scenario.albedo", value=alb,
                         allowed=", ".join(_ALBEDO))
    if alb.startswith("toms"):
        # a study that names the TOMS albedo runs with it or not at all (no silent fallback)
        from .experiments import TOMS_ALBEDO_GRIDS, thesis_albedo

        grid = TOMS_ALBEDO_GRIDS[alb]
        try:
            thesis_albedo(grid, required=True)
        except InputError as e:
            raise InputError(f"TOMS albedo data for grid {grid} not found ({e.args[0]})",
                             file=path, field="scenario.albedo", value=alb,
                             allowed="builtin, none, or a toms grid with ../shared/data/"
                             "earth_albedo or $LIGHTCURVE_SHARED_DATA present") from None
    spec = replace(
        spec, configuration=conf, controlled=sc.bool("controlled", False),
        estimators=_list("estimators", spec.estimators, ESTIMATORS),
        variants=_list("variants", spec.variants, VARIANTS),
        gyros=_list("gyros", spec.gyros, _GYROS),
        duration_s=sc.float("duration_s", 6000.0, min=10.0, max=86400.0), albedo=alb,
        text=text, source=str(path))
    sc.check_unknown()
    sim = doc.section("simulation", None)
    if sim is not None:
        allowed = _SIM_KEYS
        d = {}
        for k in list(sim.data):
            if k not in allowed:
                continue
            if k == "shadow_model":
                d[k] = sim.str(k, choices=("conical", "cylindrical"))
                continue
            d[k] = sim.bool(k) if isinstance(sim.data[k], bool) else (
                sim.str(k) if isinstance(sim.data[k], str) else sim.float(k))
        sim.check_unknown()
        spec = replace(spec, simulation=d)
    tf = doc.section("thesis_filter", None)
    if tf is not None:
        from ..io.tomlio import typed_overrides

        d = typed_overrides(tf.data, dict.fromkeys(_thesis_filter_keys(), float),
                            field="thesis_filter", file=path, what="thesis-filter parameter")
        spec = replace(spec, thesis_filter=d)
    rf = doc.section("robust_filter", None)
    if rf is not None:
        spec = replace(spec, robust_filter=_robust_filter_overrides(rf, path))
    gl = doc.section("gyroless", None)
    if gl is not None:
        from ..io.tomlio import typed_overrides
        from .okeefe2015 import GYROLESS

        spec = replace(spec, gyroless=typed_overrides(
            gl.data, dict.fromkeys(GYROLESS, float), field="gyroless", file=path,
            what="gyro-less rate setting"))
    doc.check_unknown()
    return spec


def _robust_filter_overrides(sec, path) -> dict:
    """The ``[robust_filter]`` section: fields of
    :class:`~lightcurve.css.sunline_ekf.FilterParams` with their types (booleans, integers,
    non-negative numbers)."""
    from ..io.tomlio import field_types, typed_overrides
    from .sunline_ekf import FilterParams

    return typed_overrides(sec.data, field_types(FilterParams), field="robust_filter",
                           file=path, what="robust-filter parameter")


def _thesis_filter_keys():
    """The sun-line thesis-filter parameters a study may override: ``sunline_thesis.THESIS_PRM``
    without "kind" (it selects the filter)."""
    from .sunline_thesis import THESIS_PRM

    return tuple(k for k in THESIS_PRM if k != "kind")

_SIM_KEYS = ("altitude_km", "inclination_deg", "raan_deg", "epoch_utc", "perturbations",
             "css_rate_hz", "gyro_rate_hz", "fov_half_angle_deg", "noise_sigma",
             "misalignment_sigma_deg", "scale_common_max", "scale_individual_sigma",
             "initial_rate_max_deg_s", "shadow_model")
