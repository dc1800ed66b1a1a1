"""Time per filter run of the fig. 9.4 study and the extrapolated wall time of all 9,600 runs.

Default: for each (filter, dynamics, sites) of pipelines/studies/thesis-fig9-4.toml run
``--sample`` runs (σθ = 3°, σω = 0.02°/s, r = 1 %, the seeds of the study) one after another in
this process (single-threaded BLAS, as in the study workers), after one warm-up run, and
extrapolate: total CPU = Σ_cells 100 × mean filter time of the cell's (filter, dynamics, sites)
+ the simulations (one per dynamics × sites × r × run, counted once per worker since each
worker caches its lightcurves); wall on W workers = total / W (runs are independent; no
parallel-efficiency loss assumed). The 1-minute load average is printed: on a shared machine
the numbers scale with it.
``--full DIR`` instead runs the whole study with the process pool and reports the measured
wall time. ``--grid-runs N`` runs EVERY cell N times inline in this process (one worker, so
each lightcurve is simulated once) and extrapolates the measured CPU time (process time:
what an idle machine would take, even when the machine is shared) to the study's run count:
``cpu_total = cpu(N runs per cell) × runs/N``, wall on W workers ≈ cpu_total / W (not
included: a worker may simulate a lightcurve another worker also simulated — at most
``distinct_lightcurves`` × the default mode's ``mean_simulate_s`` extra). Prints ONE JSON line.

    python benchmarks/study_fig9_4.py [--sample 4] [--workers 2] [--cpu] [--full DIR]
                                      [--grid-runs N]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lightcurve.studies.runner import execute_task, limit_blas_threads, run_study  # noqa: E402
from lightcurve.studies.study import load_study  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sample", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--full", metavar="DIR", default=None)
    ap.add_argument("--grid-runs", type=int, default=None, metavar="N",
                    help="run every cell N times inline and extrapolate the CPU time")
    ap.add_argument("--cpu", action="store_true",
                    help="time with process CPU time instead of wall time (what an idle "
                    "machine would show; the study machine is often shared)")
    a = ap.parse_args()
    study = load_study(ROOT / "pipelines/studies/thesis-fig9-4.toml")
    n_total = len(study.cells) * study.runs
    if a.full:
        t0 = time.perf_counter()
        s = run_study(study, a.full, workers=a.workers, progress=True)
        wall = time.perf_counter() - t0
        print(json.dumps({"benchmark": "study_fig9_4_full", "runs": n_total, "workers": a.workers,
                          "wall_s": round(wall, 1), "failures": sum(c["failures"] for c in s["cells"]),
                          "cpu_count": os.cpu_count()}))
        return
    if a.grid_runs:
        import tempfile

        limit_blas_threads()
        with tempfile.TemporaryDirectory() as d:
            c0 = time.process_time()
            w0 = time.perf_counter()
            s = run_study(study, d, runs=a.grid_runs, workers=1, progress=False,
                          write_report=False)
            cpu = time.process_time() - c0
            wall = time.perf_counter() - w0
        n_sims = len({(c.dynamics, c.sites, c.r_percent) for c in study.cells}) * study.runs
        per_run = cpu / (len(study.cells) * a.grid_runs)
        total = per_run * n_total
        print(json.dumps({
            "benchmark": "study_fig9_4_grid", "runs": n_total, "grid_runs_per_cell": a.grid_runs,
            "measured_cpu_s": round(cpu, 2), "measured_wall_s": round(wall, 2),
            "cpu_per_run_s": round(per_run, 4), "extrapolated_cpu_s": round(total, 1),
            "extrapolated_wall_s_on_workers": round(total / a.workers, 1),
            "distinct_lightcurves": n_sims,
            "failures": sum(c["failures"] for c in s["cells"]),
            "load_average_1min": round(os.getloadavg()[0], 2), "workers": a.workers,
            "cpu_count": os.cpu_count()}))
        return
    limit_blas_threads()
    from lightcurve.studies import runner

    tasks = study.tasks(a.sample + 1)
    sim, flt = {}, {}
    for t in tasks:
        c = t.cell
        if (c.sigma_theta_deg, c.sigma_omega_deg_s, c.r_percent) != (3.0, 0.02, 1.0):
            continue
        key = (c.filter, c.dynamics, c.sites)
        clock = time.process_time if a.cpu else time.perf_counter
        t0 = clock()
        runner._lightcurve(t.scenario_text, t.scenario_file, c.r_percent, t.sim_seed)
        t1 = clock()
        r = execute_task(t)  # the lightcurve is cached now: this is the filter + metrics
        t2 = clock()
        if r["status"] != "ok":
            print(r["error"], file=sys.stderr)
        if t.run == 0:
            continue  # warm-up (numba cache loads, first calls)
        if t1 - t0 > 1e-3:  # a fresh simulation (not a cache hit)
            sim.setdefault((c.dynamics, c.sites), []).append(t1 - t0)
        flt.setdefault(key, []).append(t2 - t1)
    ms = {k: sum(v) / len(v) for k, v in sim.items()}
    mf = {k: sum(v) / len(v) for k, v in flt.items()}
    n_sim = {}
    for c in study.cells:
        n_sim[(c.dynamics, c.sites, c.r_percent)] = (c.dynamics, c.sites)
    # every distinct simulated lightcurve is made once per worker at worst (per-process cache)
    sim_cpu = sum(study.runs * ms[v] for v in n_sim.values()) * a.workers
    flt_cpu = sum(study.runs * mf[(c.filter, c.dynamics, c.sites)] for c in study.cells)
    total_cpu = sim_cpu + flt_cpu
    print(json.dumps({
        "benchmark": "study_fig9_4", "runs": n_total, "sample_per_group": a.sample,
        "clock": "process_time" if a.cpu else "wall",
        "mean_simulate_s": {"/".join(map(str, k)): round(v, 4) for k, v in ms.items()},
        "mean_filter_run_s": {"/".join(map(str, k)): round(v, 4) for k, v in mf.items()},
        "extrapolated_cpu_s": round(total_cpu, 1),
        "extrapolated_wall_s_on_workers": round(total_cpu / a.workers, 1),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "workers": a.workers, "cpu_count": os.cpu_count()}))

if __name__ == "__main__":
    main()
