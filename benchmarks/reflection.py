"""BPF step cost with Model 3 reflection states versus attitude only (Bernard 2021 ch. 8).

Measures the bootstrap particle filter on the bundled thesis LEO fast-spin case
(pipelines/thesis/leo-ic1-fast-spin-controlled-1site.toml: controlled, Socorro, 73 epochs,
eclipse ignored as in the thesis; truth shape perturbed per §10.1 by the scenario's
``[reflection]`` section) twice per particle count:

* ``attitude`` — attitude-only state (GRP error + rate, no reflection states);
* ``model3`` — the same plus Model 3's 24 extra states (ξ, a, m, A of the six cube_1u facets,
  reparameterised per eq. 8.41–8.44, constant dynamics eq. 8.39).

The plain bootstrap filter is timed (``progressive=False``: exactly one prediction per particle
and epoch) so that µs per particle·step compares like with like. Each configuration runs in a
fresh subprocess after a small warm-up (numba cache), so its peak RSS (ru_maxrss, whole process)
is its own. The §10.7/§10.8 accuracy runs of the BPF are ``benchmarks/reflection_bpf.py``; the
emcee posterior benchmark is ``benchmarks/reflection_emcee.py``.

Usage: python benchmarks/reflection.py [--particles 10000 100000]
Prints ONE JSON line (µs per particle·step, particle·steps/s, peak RSS, the Model 3 / attitude
cost ratio per particle count, ``cpu_count``, numba threads, the 1-minute load average).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reflection_bpf import print_with_machine  # noqa: E402  (shared JSON footer)

CHILD = r"""
import json, resource, sys, time, warnings
warnings.simplefilter("ignore")
sys.path.insert(0, sys.argv[3])
from reflection_bpf import scenario_with_reflection
from lightcurve.studies.simulate import simulate
from lightcurve.filters import build_problem, run_bpf
from lightcurve.filters.facet_states import FacetParameterStates

kind, N = sys.argv[1], int(sys.argv[2])
lc = simulate(scenario_with_reflection(), 1)
prob = build_problem(lc, seed=0, sigma_theta_deg=3.0)
kw = {}
if kind == "model3":
    kw["facets"] = FacetParameterStates(prob.model.shape)
run_bpf(prob, particles=500, seed=0, progressive=False, **kw)   # warm-up (numba cache)
t0 = time.perf_counter()
est = run_bpf(prob, particles=N, seed=0, progressive=False, **kw)
dt = time.perf_counter() - t0
n = len(est)
print(json.dumps({"states": kind, "extra_states": int(kw["facets"].dim) if kw else 0,
                  "particles": N, "epochs": n, "runtime_s": dt,
                  "us_per_particle_step": dt / (N * n) * 1e6,
                  "particle_steps_per_s": N * n / dt,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                  "final_att_error_rss_deg": est.summary().get("final_att_error_rss_deg")}))
"""


def step_cost(particles):
    """Time attitude-only and Model 3 BPF runs, each in its own subprocess (list of rows)."""
    here = os.path.dirname(os.path.abspath(__file__))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.path.dirname(here) + os.pathsep + env.get("PYTHONPATH", "")
    rows = []
    for n in particles:
        for kind in ("attitude", "model3"):
            out = subprocess.run([sys.executable, "-c", CHILD, kind, str(n), here], env=env,
                                 capture_output=True, text=True, check=True)
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    ratio = {}
    for n in particles:
        a = [r for r in rows if r["particles"] == n and r["states"] == "attitude"][0]
        b = [r for r in rows if r["particles"] == n and r["states"] == "model3"][0]
        ratio[str(n)] = b["us_per_particle_step"] / a["us_per_particle_step"]
    return {"benchmark": "reflection", "mode": "step_cost",
            "filter": "plain bootstrap (progressive=False)", "runs": rows,
            "model3_over_attitude_cost": ratio}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, nargs="+", default=[10_000, 100_000],
                    help="particle counts to time (default: 10000 100000)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    out = step_cost(args.particles)
    print_with_machine(out, t0)


if __name__ == "__main__":
    main()
