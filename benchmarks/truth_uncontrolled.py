"""Time per uncontrolled truth trajectory of the thesis cases: compiled named torques vs the
Python torque-model path.

For each scenario (default: the five fast-spin uncontrolled one-site cases of Fig. 9.4 and
B.1–B.4 with their 5 s epochs over 0–360 s), simulates ``--runs`` truths (seeds 0, 1, …) with
``UncontrolledTruth(torques=[...])`` — the right-hand side calls
``lightcurve.dynamics.torques.environment_torque_nb`` — and the same truths with the same
torque objects passed as ``torque_models`` (one Python call per torque per right-hand-side
evaluation), after one warm-up truth each. Prints ONE JSON line per scenario: seconds per truth
for both paths, their ratio, the largest difference of the two trajectories (quaternion
components and rad/s), the core count and the 1-minute load average.

    python benchmarks/truth_uncontrolled.py [--runs 5] [SCENARIO.toml ...]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
try:
    import lightcurve  # noqa: F401
except ModuleNotFoundError:  # run from a source checkout without installing
    sys.path.insert(0, str(ROOT))

from lightcurve.dynamics import UncontrolledTruth  # noqa: E402
from lightcurve.studies.scenario import load_scenario  # noqa: E402
from lightcurve.studies.simulate import initial_attitude  # noqa: E402

DEFAULT = [ROOT / "pipelines" / "thesis" / f"{n}.toml" for n in (
    "leo-ic1-fast-spin-uncontrolled-1site", "meo-fast-spin-cubesat-uncontrolled-1site",
    "meo-fast-spin-scaled-uncontrolled-1site", "geo-fast-spin-cubesat-uncontrolled-1site",
    "geo-fast-spin-scaled-uncontrolled-1site")]


def _truth(sc, seed, models=None):
    at = sc.attitude
    q0, w0 = initial_attitude(sc)
    J = at.inertia_kg_m2 if at.inertia_kg_m2 is not None else sc.shape.inertia_kg_m2
    eta = np.radians(at.eta_sigma_deg_s2)
    if models is None:
        return UncontrolledTruth(q0, w0, J, torques=at.torques, eta_sigma_rad_s2=eta, rng=seed,
                                 shape=sc.shape, orbit=sc.orbit, epoch_utc=sc.epoch_utc, t0_s=0.0,
                                 torque_forms=at.torque_forms)
    return UncontrolledTruth(q0, w0, J, torque_models=models, eta_sigma_rad_s2=eta, rng=seed, t0_s=0.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*", type=Path, help="uncontrolled scenario TOML files")
    ap.add_argument("--runs", type=int, default=5, help="truths per scenario and path (default 5)")
    args = ap.parse_args()
    t = np.arange(0.0, 360.1, 5.0)
    for path in args.scenarios or DEFAULT:
        sc = load_scenario(path)
        if sc.attitude.dynamics != "uncontrolled" or not sc.attitude.torques:
            raise SystemExit(f"{path}: not an uncontrolled scenario with named torques")
        models = _truth(sc, 0).build_named_torques(0.0, float(t[-1]))
        out = {}
        for label, mk in (("compiled", lambda s: _truth(sc, s)), ("python", lambda s: _truth(sc, s, models))):
            mk(0).simulate(t)  # warm-up: numba cache, ephemeris
            t0 = time.perf_counter()
            out[label] = [mk(s).simulate(t) for s in range(args.runs)]
            out[label + "_s"] = (time.perf_counter() - t0) / args.runs
        dq = max(float(np.max(np.abs(a[0] - b[0]))) for a, b in zip(out["compiled"], out["python"]))
        dw = max(float(np.max(np.abs(a[1] - b[1]))) for a, b in zip(out["compiled"], out["python"]))
        print(json.dumps({
            "scenario": path.name, "runs": args.runs, "torques": list(sc.attitude.torques),
            "torque_forms": sc.attitude.torque_forms,
            "compiled_s_per_truth": round(out["compiled_s"], 4),
            "python_s_per_truth": round(out["python_s"], 4),
            "speedup": round(out["python_s"] / out["compiled_s"], 1),
            "max_abs_dq": dq, "max_abs_domega_rad_s": dw,
            "cores": os.cpu_count(), "load_1min": round(os.getloadavg()[0], 2),
        }), flush=True)


if __name__ == "__main__":
    main()
