"""Quick numerical self-checks of an installation (``lightcurve selfcheck``).

Each check is independent and prints one line: rotation algebra against scipy, exact
constant-rate attitude propagation against RK4 integration, angular-momentum conservation of
the rigid-body integrator, and availability of the offline ephemeris (skyfield-data DE421).
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["run_selfcheck", "CHECKS"]


def _check_rotations():
    from scipy.spatial.transform import Rotation

    from . import rotations as R

    rng = np.random.default_rng(0)
    q = R.quat_normalize(rng.normal(size=(1000, 4)))
    err = np.abs(R.to_scipy(q).as_matrix() - R.quat_to_dcm(q)).max()
    p = R.quat_normalize(rng.normal(size=(1000, 4)))
    err2 = np.abs(R.quat_to_dcm(R.quat_mult(q, p)) - R.quat_to_dcm(q) @ R.quat_to_dcm(p)).max()
    # scipy's own composition: active rotations compose the other way round
    err3 = np.abs((Rotation.from_matrix(R.quat_to_dcm(q)) * Rotation.from_matrix(R.quat_to_dcm(p))).as_matrix()
                  - R.quat_to_dcm(R.quat_mult(q, p))).max()
    worst = max(err, err2, err3)
    return worst < 1e-12, f"max |A(q) - scipy| = {worst:.1e} over 1000 random attitudes"


def _check_kinematics():
    from .dynamics.kinematics import propagate_constant_rate
    from .dynamics.integrators import rk4_propagate_nb

    q0 = np.array([[0.5, 0.5, 0.5, 0.5]])
    w = np.radians([[2.0, 1.0, 3.6]])
    J = np.diag([1.0, 1.0, 1.0])
    exact = propagate_constant_rate(q0[0], w[0], 10.0)
    q, ww = rk4_propagate_nb(q0.copy(), w.copy(), J, np.linalg.inv(J), 0.01, 1000)
    err = min(np.abs(q[0] - exact).max(), np.abs(q[0] + exact).max())
    return err < 1e-9, f"exact constant-rate step vs RK4 (10 s, dt 0.01 s): {err:.1e}"


def _check_momentum():
    from .dynamics.integrators import rk4_propagate_nb
    from .rotations import quat_rotate_inv

    J = np.diag([10.5, 8.0, 7.5])
    q0 = np.array([[1.0, 0, 0, 0]])
    w0 = np.array([[0.1, 0.02, -0.05]])
    H0 = quat_rotate_inv(q0[0], J @ w0[0])
    q, w = rk4_propagate_nb(q0.copy(), w0.copy(), J, np.linalg.inv(J), 0.05, 2000)
    H1 = quat_rotate_inv(q[0], J @ w[0])
    rel = np.linalg.norm(H1 - H0) / np.linalg.norm(H0)
    return rel < 1e-6, f"torque-free RK4, 100 s asymmetric body: |ΔH|/|H| = {rel:.1e}"


def _check_ephemeris():
    from .geometry.time import sun_position_gcrs

    r = sun_position_gcrs("2020-03-01T08:08:40Z", np.array([0.0]))
    d_au = np.linalg.norm(r[0]) / 1.495978707e11
    return 0.98 < d_au < 1.02, f"offline DE421 Sun distance on 2020-03-01: {d_au:.5f} au"


CHECKS = (
    ("rotation algebra vs scipy", _check_rotations),
    ("attitude kinematics", _check_kinematics),
    ("rigid-body momentum conservation", _check_momentum),
    ("offline ephemeris (skyfield-data)", _check_ephemeris),
)


def run_selfcheck(verbose: bool = True) -> bool:
    """Run every check; print one line each; return True when all pass."""
    ok_all = True
    for name, fn in CHECKS:
        t0 = time.perf_counter()
        try:
            ok, detail = fn()
        except Exception as exc:  # a failing check reports, never crashes the others
            ok, detail = False, f"{type(exc).__name__}: {exc}"
        ok_all &= bool(ok)
        if verbose or not ok:
            print(f"[{'ok' if ok else 'FAIL'}] {name}: {detail} ({time.perf_counter() - t0:.1f} s)")
    return ok_all
