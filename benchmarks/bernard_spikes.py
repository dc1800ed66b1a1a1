"""Are the specular spikes of the controlled fast-spinning thesis curves absent from the
uncontrolled ones, as Bernard §9.4.5 states (Fig. 9.19, GEO)?

For each thesis Monte Carlo study (Fig. 9.4 LEO, B.1–B.4 MEO/GEO) the script takes the
one-site, σω 0.02°/s, 1 % cell of each dynamics model — the Fig. 9.19 case in GEO (§9.4.5:
"the CubeSat shape model … σω = 0.02 deg/s, … r_percent = 1 %") — and builds the simulated
truths of the study's first ``--runs`` runs exactly as the study does (same scenario, seeds and
options). The initial estimate and σθ do not enter the truth. On each noise-free curve it finds
the spike epochs: those more than ``--brighter`` mag brighter than the median of the same
site's epochs within ±4 of them (:func:`lightcurve.studies.runner.glint_height`, the rule of the
``hide_glints_mag`` diagnostic). Per study and dynamics it reports the spike count of each run,
the largest spike height (mag above the local median) of each run and the spike times of run 0.

    python benchmarks/bernard_spikes.py [--runs 20] [--brighter 2] [--studies NAME ...]
        [-o OUT.json]

Prints one line per study and dynamics, then ONE JSON line with every number (also written to
``-o``); ``lightcurve reproduction --spikes OUT.json`` turns it into the §9.4.5 row of
docs/reproduction.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lightcurve.io.atomic import atomic_write_text  # noqa: E402
from lightcurve.studies.runner import glint_height, task_lightcurve  # noqa: E402
from lightcurve.studies.study import load_study  # noqa: E402

#: the thesis Monte Carlo studies and what they fly (regime, shape)
STUDIES = (("thesis-fig9-4", "LEO", "CubeSat"), ("thesis-fig-b1-meo-cubesat", "MEO", "CubeSat"),
           ("thesis-fig-b2-meo-scaled", "MEO", "scaled"),
           ("thesis-fig-b3-geo-cubesat", "GEO", "CubeSat"),
           ("thesis-fig-b4-geo-scaled", "GEO", "scaled"))
#: the Fig. 9.19 cell (§9.4.5): one site, σω 0.02°/s, r 1 %
CELL = dict(sites=1, sigma_omega_deg_s=0.02, r_percent=1.0)


def truths(study, dynamics: str, runs: int):
    """The simulated curves of runs 0…runs−1 of the study's ``CELL`` with ``dynamics``, built
    as the study runner builds them."""
    cells = [c for c in study.cells if c.dynamics == dynamics
             and all(getattr(c, k) == v for k, v in CELL.items())]
    if not cells:
        return []
    cell = cells[0]    # the truth does not depend on the filter or on σθ
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return [task_lightcurve(t) for t in study.tasks(runs) if t.cell == cell]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=20,
                    help="truths per study and dynamics: the study's first N runs (default 20)")
    ap.add_argument("--brighter", type=float, default=2.0,
                    help="spike: noise-free magnitude more than this many mag brighter than the "
                    "median of the same site's epochs within ±4 of it (default 2)")
    ap.add_argument("--studies", nargs="+", default=[n for n, _, _ in STUDIES],
                    choices=[n for n, _, _ in STUDIES], metavar="NAME",
                    help="the thesis studies to read (default: all five tables)")
    ap.add_argument("-o", "--output", type=Path, default=None, help="also write the JSON here")
    a = ap.parse_args(argv)
    if a.runs < 1 or not a.brighter > 0:
        ap.error("--runs must be >= 1 and --brighter > 0")
    t0 = time.perf_counter()
    cases = []
    for name, regime, shape in STUDIES:
        if name not in a.studies:
            continue
        study = load_study(ROOT / "pipelines" / "studies" / f"{name}.toml")
        for dynamics in ("controlled", "uncontrolled"):
            curves = truths(study, dynamics, a.runs)
            if not curves:
                continue
            heights = [glint_height(c) for c in curves]
            spikes = [int(np.sum(h > a.brighter)) for h in heights]
            largest = [round(float(np.nanmax(h)), 3) for h in heights]
            t_run0 = np.asarray(curves[0].t, float)[heights[0] > a.brighter]
            cases.append({"study": name, "regime": regime, "shape": shape,
                          "dynamics": dynamics, **CELL, "spikes": spikes,
                          "largest_mag": largest,
                          "spike_times_s_run0": np.round(t_run0, 1).tolist()})
            print(f"{name:28s} {dynamics:12s} spikes per run: median {np.median(spikes):g} "
                  f"(min {min(spikes)}, max {max(spikes)}); largest "
                  f"{np.median(largest):.2f} mag above the local median (median over "
                  f"{len(curves)} runs); run 0 at t = {t_run0.tolist()} s", flush=True)
    line = json.dumps({"benchmark": "bernard_spikes", "runs": a.runs,
                       "brighter_mag": a.brighter, "cases": cases,
                       "wall_s": round(time.perf_counter() - t0, 1),
                       "cpu_count": os.cpu_count(), "load": os.getloadavg()[0]})
    if a.output is not None:
        atomic_write_text(a.output, line + "\n")
    print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
