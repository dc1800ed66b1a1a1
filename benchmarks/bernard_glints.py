"""Do the specular glints decide a Bernard Monte Carlo cell? Each selected cell of a thesis study
is run twice on the study's own seeds: as the study runs it, and with the glint epochs hidden
from the filter (the truth, the initial estimates and the noise draws are unchanged).

A glint epoch is one whose noise-free magnitude is more than ``--brighter`` mag brighter than
the median noise-free magnitude of the nearby epochs (study option ``hide_glints_mag``,
:func:`lightcurve.studies.runner.hide_glints`):
the sharp specular spikes of the +X facet (m = 0.04, Bernard Table 9.2). The thesis shows these
"specular spikes" in the controlled MEO curve (§9.4.2, Fig. 9.9b) and states that the
uncontrolled fast-spinning curves lack them (§9.4.5, Fig. 9.19).

For each cell the script prints the runs outside 3σ of the six final error components
(θx θy θz ωx ωy ωz, Bernard §9.3.1), the traffic-light colour of the thesis's rule
(:func:`lightcurve.studies.metrics.traffic_light`, scaled to the run count), the published
colour, and the mean final attitude error over the runs with its standard error (a mean more
than 3 standard errors from zero is a bias of the estimator on this geometry: every run of a
cell flies the same truth attitude up to the process noise).

    python benchmarks/bernard_glints.py pipelines/studies/thesis-fig-b1-meo-cubesat.toml \\
        --filter mekf --dynamics uncontrolled --r 10 --runs 30 [--brighter 2]

Prints one line per cell and pass, then ONE JSON line with every number.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lightcurve.studies.agreement import thesis_color  # noqa: E402
from lightcurve.studies.metrics import outside_3sigma, traffic_light  # noqa: E402
from lightcurve.studies.runner import execute_task, limit_blas_threads  # noqa: E402
from lightcurve.studies.study import load_study  # noqa: E402


def run_cell(tasks, hide_glints_mag=None):
    """Run ``tasks``; with ``hide_glints_mag`` as the study option of that name sets it."""
    out, err, n_epochs = [], [], []
    for t in tasks:
        if hide_glints_mag is not None:
            opts = {**dict(t.options), "hide_glints_mag": float(hide_glints_mag)}
            t = replace(t, options=tuple(sorted(opts.items())))
        r = execute_task(t)
        if r["status"] != "ok":
            out.append(np.ones(6, bool))
            continue
        out.append(outside_3sigma(r["att_error_deg"][-1], r["att_sigma_deg"][-1],
                                  r["omega_error_rad_s"][-1], r["omega_sigma_rad_s"][-1]))
        err.append(r["att_error_deg"][-1])
        n_epochs.append(len(r["t"]))
    err = np.array(err).reshape(-1, 3)
    counts = np.sum(out, axis=0).astype(int)
    return {"outside_3sigma": counts.tolist(), "color": traffic_light(counts, len(tasks)),
            "mean_att_error_deg": np.round(err.mean(0), 3).tolist() if len(err) else None,
            "se_att_error_deg": (np.round(err.std(0, ddof=1) / np.sqrt(len(err)), 3).tolist()
                                 if len(err) > 1 else None),
            "epochs": int(np.median(n_epochs)) if n_epochs else 0}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("study", help="a thesis study TOML (pipelines/studies/thesis-*.toml)")
    ap.add_argument("--filter", nargs="+", default=None, help="mekf, ukf (default: the study's)")
    ap.add_argument("--dynamics", nargs="+", default=None, help="controlled, uncontrolled")
    ap.add_argument("--sites", nargs="+", type=int, default=None, help="1, 2")
    ap.add_argument("--sigma-theta-deg", nargs="+", type=float, default=None)
    ap.add_argument("--sigma-omega-deg-s", nargs="+", type=float, default=None)
    ap.add_argument("--r", nargs="+", type=float, default=None, help="r_percent: 1, 10")
    ap.add_argument("--runs", type=int, default=30, help="runs per cell (the study's first N)")
    ap.add_argument("--brighter", type=float, default=2.0,
                    help="glint: noise-free magnitude more than this many mag brighter than "
                    "the median of the same site's epochs within ±4 of it (default 2)")
    a = ap.parse_args()
    limit_blas_threads()
    study = load_study(a.study)
    want = {"filter": a.filter, "dynamics": a.dynamics, "sites": a.sites,
            "sigma_theta_deg": a.sigma_theta_deg, "sigma_omega_deg_s": a.sigma_omega_deg_s,
            "r_percent": a.r}
    cells = [c for c in study.cells
             if all(v is None or getattr(c, k) in v for k, v in want.items())]
    if not cells:
        sys.exit(f"{a.study}: no cell matches the selection")
    tasks = list(study.tasks(a.runs))
    rows = []
    t0 = time.perf_counter()
    for c in cells:
        ct = [t for t in tasks if t.cell == c]
        row = {"cell": c.as_dict(), "thesis": thesis_color(study.thesis_table, c.as_dict())}
        for name, mag in (("all_epochs", None), ("glints_hidden", a.brighter)):
            row[name] = run_cell(ct, mag)
            r = row[name]
            print(f"{c.filter} {c.dynamics} sites={c.sites} σθ={c.sigma_theta_deg:g} "
                  f"σω={c.sigma_omega_deg_s:g} r={c.r_percent:g}% {name:13s} "
                  f"epochs {r['epochs']:3d}  outside {r['outside_3sigma']}  {r['color']:6s} "
                  f"(thesis {row['thesis']})  mean θ error {r['mean_att_error_deg']} ± "
                  f"{r['se_att_error_deg']} deg", flush=True)
        rows.append(row)
    print(json.dumps({"benchmark": "bernard_glints", "study": str(a.study), "runs": a.runs,
                      "brighter_mag": a.brighter, "cells": rows,
                      "wall_s": round(time.perf_counter() - t0, 1), "cpu_count": os.cpu_count(),
                      "load": os.getloadavg()[0]}))


if __name__ == "__main__":
    main()
