"""The CUDA backend of the particle filter under numba's CUDA simulator (no GPU needed).

The kernels run in a subprocess with ``NUMBA_ENABLE_CUDASIM=1`` (the variable must be set before
numba.cuda is imported). With the same seed the GPU filter draws the same counter-based normals
as the CPU filter and runs the same per-particle functions, so its posterior equals the CPU
one to round-off (the block reductions sum in another order): a stronger check than a
statistical comparison, which is added for the normals kernel (Kolmogorov–Smirnov against
N(0, 1), false-alarm rate 1e-3). The robust run uses the "separate" rejuvenation: the joint
kernel drops a cloud component whose spread is exactly zero, and for a collapsed rate cloud
(spread ~1e-17) that decision, and with it the number of normals drawn, follows the last bit
of the reduction (docs/bpf.md). Small sizes: every simulated CUDA thread is a Python thread
(about 30 s in all). Four epochs with 64 particles (two simulator blocks) call every stage the
six-epoch run calls, plus the log-likelihood kernel: prediction, normals, weights, resampling,
gathers, both roughenings and every reduction.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(importlib.util.find_spec("numba_cuda") is None,
                                reason="numba-cuda not installed (pip install 'lightcurve[gpu]')")

SCRIPT = r"""
import json, sys
import numpy as np
from scipy import stats
sys.path.insert(0, sys.argv[1])
from filters_synth import make_curve
from lightcurve.core import particles as CP
from lightcurve.filters import build_problem, run_bpf
from lightcurve.filters.bpf import BPFConfig, _Draws
from lightcurve.filters.bpf_gpu import _CudaOps, gpu_available, run_bpf_gpu

out = {"available": gpu_available()[0]}
p = build_problem(make_curve(n=4, seed=3), seed=2, sigma_theta_deg=10.0)
for name, cfg in (("thesis", BPFConfig.thesis(particles=64)),
                  ("robust_plain", BPFConfig(particles=64, progressive=False,
                                             rejuvenation="separate"))):
    g = run_bpf_gpu(p, cfg, seed=1)
    c = run_bpf(p, cfg, seed=1)
    out[name] = {"dq": float(np.max(np.abs(g.q - c.q))),
                 "dw": float(np.max(np.abs(g.omega_rad_s - c.omega_rad_s))),
                 "dcov": float(np.max(np.abs(g.cov - c.cov) / (np.abs(c.cov) + 1e-30))),
                 "neff": float(np.max(np.abs(g.n_eff - c.n_eff))),
                 "flags_equal": bool(np.array_equal(g.flags, c.flags)),
                 "backend": g.meta["bpf"]["backend"]}
ops = _CudaOps()
d = _Draws(5, "philox")
z = ops.to_host(ops.normals(d, ops.empty((4096, 1))))
zc = np.empty((4096, 1))
CP.philox_normals(d.k0, d.k1, 0, zc)
out["normals_equal_cpu"] = bool(np.array_equal(z, zc))
out["ks_p"] = float(stats.kstest(z[:, 0], "norm").pvalue)
print(json.dumps(out))
"""


def test_gpu_kernels_reproduce_the_cpu_filter_under_the_simulator():
    here = Path(__file__).resolve().parent
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(here)], capture_output=True,
                       text=True, env=env, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["available"]
    for name in ("thesis", "robust_plain"):
        o = out[name]
        assert o["backend"] == "cuda"
        assert o["dq"] < 1e-12 and o["dw"] < 1e-15 and o["neff"] < 1e-9, (name, o)
        assert o["dcov"] < 1e-8 and o["flags_equal"], (name, o)
    assert out["normals_equal_cpu"]
    assert out["ks_p"] > 1e-3


def test_gpu_backend_refuses_what_it_does_not_do():
    from filters_synth import make_curve

    from lightcurve.errors import InputError
    from lightcurve.filters import build_problem
    from lightcurve.filters.bpf_gpu import gpu_available, run_bpf_gpu

    p = build_problem(make_curve(n=4, seed=3), seed=2, sigma_theta_deg=3.0)
    ok, why = gpu_available()
    if not ok:   # no device in this process (the simulator is not enabled here)
        with pytest.raises(InputError, match="device"):
            run_bpf_gpu(p, particles=64)
        assert why
    else:        # pragma: no cover - a machine with a GPU
        with pytest.raises(NotImplementedError):
            run_bpf_gpu(p, particles=64, attitude="truth")
