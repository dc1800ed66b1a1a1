"""Time the expensive physics effects on a synthetic 200-epoch LEO context.

Prints one JSON line: seconds per evaluation of the baseline, Earthshine (built-in 10° map and,
if present, the CERES 1° map), exposure smearing (12 nodes) and self-shadowing of the
rocket-body mesh (4×4 samples per triangle) and of the box-wing mesh (16×16, the registry
default, and 48×48, what the diagnosis uses; each evaluation with a fresh effect, i.e. ray
casting included, and once more with the visibility cache warm), plus os.cpu_count().
"""

import json
import os
import sys
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "physics"))

from lightcurve._paths import shared_data_dir  # noqa: E402
from lightcurve.photometry import load_shape  # noqa: E402
from lightcurve.physics import get_effect  # noqa: E402
from physics_synth import make_ctx  # noqa: E402


def timed(fn, reps=3):
    fn()  # compile / cache
    t0 = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t0) / reps


def main():
    n = 200
    cube = make_ctx(load_shape("cube_1u"), n=n, sun_dir=(0.3, 1.0, 0.2), ignore_eclipse=True)
    rb = make_ctx(load_shape("rocket_body"), n=n, sun_dir=(0.3, 1.0, 0.2), ignore_eclipse=True)
    out = {"n_epochs": n, "cpu_count": os.cpu_count()}
    out["baseline_s"] = timed(lambda: cube.magnitude())
    out["earthshine_builtin10_s"] = timed(lambda: get_effect("earthshine").apply(cube, {}))
    sd = shared_data_dir()
    if sd is not None and (sd / "earth_albedo/Earth_ALB_2018_CERES_All_1x1.csv").is_file():
        e = get_effect("earthshine", albedo=str(sd / "earth_albedo/Earth_ALB_2018_CERES_All_1x1.csv"))
        out["earthshine_ceres1_s"] = timed(lambda: e.apply(cube, {}), reps=1)
    out["exposure_smearing_12_s"] = timed(lambda: get_effect("exposure_smearing").apply(cube, {"exposure_s": 2.0}))
    # a fresh effect per call: its flux model caches visibilities per direction set
    out["self_shadowing_rocket_body_s"] = timed(
        lambda: get_effect("self_shadowing", skip_convex=False, subdivisions=4).apply(rb, {}))
    bw = make_ctx(load_shape("box_wing_mesh"), n=n, sun_dir=(0.3, 1.0, 0.2), ignore_eclipse=True)
    for sub in (16, 48):
        out[f"self_shadowing_box_wing_{sub}_s"] = timed(
            lambda: get_effect("self_shadowing", subdivisions=sub).apply(bw, {}))
    warm = get_effect("self_shadowing", subdivisions=48)
    out["self_shadowing_box_wing_48_cached_s"] = timed(lambda: warm.apply(bw, {}))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
