"""Measurement-update cost of the full CSS calibration filter at 1°, 5° and 10° albedo grids.

Compared with O'Keefe (2015) table 4.4 (C implementation): 6141 µs (1°×1.25°), 506 µs (5°),
180 µs (10°).  Our filter evaluates only the cells inside the latitude/longitude window of
the cap visible from the spacecraft, and among those only the sunlit ones in view.

Set-up: dual pyramid (8 sensors, 70° FOV), state of 6 + 4·8 = 38 (30 estimated + 8
considered), spacecraft at 400 km over a sunlit mid-latitude point, Sun 30° from the zenith,
random attitude with several sensors lit.  Maps: the CERES 2018 all-sky maps from
../shared/data/earth_albedo (the built-in zonal model at the same resolution when absent).

Prints one JSON line: per resolution the median µs of one update (model + Jacobian + Joseph
consider update), of the model alone, and the number of cells visited; plus os.cpu_count().
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from lightcurve._paths import shared_data_dir
from lightcurve.css.albedo import builtin_albedo_map, load_albedo_map
from lightcurve.css.calibration import (AlbedoCells, CalibrationParams, albedo_vectors_nb,
                                        calibration_measurement_nb, calibration_update_nb,
                                        initial_state)
from lightcurve.css.configurations import dual_pyramid
from lightcurve.css.sensors import normal_to_azel
from lightcurve.core.rotations import euler321_to_dcm_nb
from lightcurve.rotations import quat_rotate_inv

from lightcurve.css.okeefe2015 import THESIS_RESULTS

THESIS_TABLE_4_4_US = {res: THESIS_RESULTS["table4_4"][g][1][0]    # update means, µs
                       for res, g in ((1, "1p25x1"), (5, "5x5"), (10, "10x10"))}


def _map(res):
    d = shared_data_dir()
    if d is not None:
        f = d / "earth_albedo" / f"Earth_ALB_2018_CERES_All_{res}x{res}.csv"
        if f.is_file():
            return load_albedo_map(f), "CERES"
    return builtin_albedo_map(float(res)), "builtin"


def _timeit(fn, n):
    fn()  # compile / warm up
    ts = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        fn()
        ts[i] = time.perf_counter() - t0
    return float(np.median(ts) * 1e6)


def main(n=2000):
    css = dual_pyramid()
    N = css.n_sensors
    prm = CalibrationParams()
    az0, el0 = normal_to_azel(css.normals)
    cf = np.cos(css.fov_half_angle_rad)
    hor = np.zeros((N, 3))
    lat, lon = np.radians(35.0), np.radians(20.0)
    up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    east = np.array([-np.sin(lon), np.cos(lon), 0.0])
    r_E = (6378137.0 + 400e3) * up
    s_E = np.cos(np.radians(30)) * up + np.sin(np.radians(30)) * east
    theta = 0.0
    s_N = s_E.copy()
    # attitude: body -z (the lower pyramid) toward nadir, rotated about it
    q = np.array([0.2, 0.9, 0.1, 0.37])
    q /= np.linalg.norm(q)
    rng = np.random.default_rng(0)
    x0, P0 = initial_state(css, q, prm)
    A = rng.normal(size=P0.shape) * 1e-3
    P0 = P0 + A @ A.T
    y = np.clip(rng.uniform(0, 1, N), 0, None)
    out = {"benchmark": "css_calibration_update", "cpu_count": os.cpu_count(),
           "state_size": int(x0.size), "sensors": N, "results": {}}
    nu = np.empty(N)
    sv = np.empty(N)
    for res in (1, 5, 10):
        amap, src = _map(res)
        cells = AlbedoCells.from_map(amap)
        args = cells.args()
        h = calibration_measurement_nb(x0, az0, el0, cf, hor, s_N, 1.0, theta, r_E, s_E, *args,
                                       np.zeros(N))[0]
        y_use = np.where(h > 0.05, h + 0.01, y)

        def upd():
            x, P = x0.copy(), P0.copy()
            calibration_update_nb(x, P, y_use, prm.as_array(), az0, el0, cf, hor, s_N, 1.0,
                                  theta, r_E, s_E, *args, nu, sv, np.empty(N))

        def model():
            calibration_measurement_nb(x0, az0, el0, cf, hor, s_N, 1.0, theta, r_E, s_E, *args,
                                       np.zeros(N))

        E = euler321_to_dcm_nb(np.array([theta, 0.0, 0.0]))   # ECI → Earth-fixed
        nE = np.array([E @ quat_rotate_inv(q, nn) for nn in css.normals])
        _, _, count = albedo_vectors_nb(*args, r_E, s_E, nE, cf, hor, np.zeros(N))
        out["results"][f"{res}deg"] = {
            "map": src, "cells_total": int(cells.nlat * cells.nlon), "cells_visited": int(count),
            "update_us": round(_timeit(upd, n), 1), "model_us": round(_timeit(model, n), 1),
            "thesis_table_4_4_us": THESIS_TABLE_4_4_US[res],
            "sensors_used": int(np.sum(h > 0.05))}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
