"""Compile the suite's slowest numba kernels into numba's on-disk cache, in a second process.

Started by tests/conftest.py once a session of many tests is collected (one numba thread, its
own process group; stopped when the session ends). Each step calls the package the way the tests
do, on tiny inputs, so that the kernel signatures are the ones the tests use; the test process
then loads those kernels from the cache instead of compiling them. Order: the largest kernels
the suite needs soonest first: the suite reaches the CSS tests before the particle-filter tests
(measured cold: the closed CSS loop ≈ 60 s, the CSS calibration and sun-line filters ≈ 35 s, the
particle filter ≈ 45 s in all). A step that fails is skipped: this process never decides a
test's outcome, it only fills the cache.
"""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path

# import the same package as the test process (its parent folder comes from conftest)
_parent = os.environ.get("LIGHTCURVE_PRECOMPILE_PATH")
if _parent:
    sys.path.insert(0, _parent)
sys.path.insert(0, str(Path(__file__).resolve().parent / "filters"))


def _css_loop_and_calibration():
    from lightcurve.css.calibration import (CalibrationParams, run_calibration,
                                            simulate_calibration_case)

    c = simulate_calibration_case(1, duration_s=60.0)
    run_calibration(c.css_nominal, c.t, c.Y, c.gyro, c.sun_N, c.lit, c.r_I_m, c.epoch_utc,
                    params=CalibrationParams().for_gyro(c.info["spec"]),
                    q_star=c.q_star, star_valid=c.star_valid)


def _css_filters():
    import numpy as np

    from lightcurve.css.configurations import configuration_by_name
    from lightcurve.css.sunline_ekf import run_filter

    css = configuration_by_name("dual_pyramid", fov_half_angle_deg=60.0)
    normals = np.asarray(css.normals, float)
    t = np.arange(20) * 0.5
    s = np.array([0.6, 0.0, 0.8])
    Y = np.clip(normals @ s, 0.0, None)[None, :].repeat(t.size, axis=0)
    for kind in ("ekf", "eckf"):
        run_filter(kind, t, Y, normals, gyro=np.zeros((t.size, 3)))
        run_filter(kind, t, Y, normals)


def _particle_filter():
    from filters_synth import make_curve

    from lightcurve.filters import build_problem, run_bpf
    from lightcurve.filters.bpf import BPFConfig

    p = build_problem(make_curve(n=6, seed=3), seed=2, sigma_theta_deg=10.0)
    run_bpf(p, BPFConfig.thesis(particles=64), seed=1)
    run_bpf(p, particles=64, seed=1)
    run_bpf(p, BPFConfig(particles=64, progressive=False, rejuvenation="separate"), seed=1)


def _vmm():
    from lightcurve.css.vmm import run_vmm_smm, simulate_vmm_case

    run_vmm_smm(simulate_vmm_case(1, duration_s=20.0))


def _filters_and_reflection():
    from lightcurve.warmup import warm_up

    warm_up(reflection=True)


STEPS = (_css_loop_and_calibration, _css_filters, _vmm, _particle_filter,
         _filters_and_reflection)


def main() -> int:
    warnings.simplefilter("ignore")
    for step in STEPS:
        try:
            step()
        except Exception:  # noqa: BLE001 - a failed step only leaves its kernels uncompiled
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
