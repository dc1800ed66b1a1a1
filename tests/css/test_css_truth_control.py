"""Truth simulation (§2.4), MRP sun-pointing control (eq. 3.64) and the tumbling Monte Carlo
acceptance of the sun-line filters."""

import numpy as np
import pytest

from lightcurve.css.configurations import dual_pyramid
from lightcurve.css.control import mrp_control_nb, sun_pointing_mrp
from lightcurve.css.study import StudySpec, run_case, settled_mask
from lightcurve.css.truth import Scenario, Spacecraft, simulate, wheel_pyramid
from lightcurve.rotations import mrp_to_dcm, quat_rotate_inv


def test_sun_pointing_mrp_definition():
    # [BR] h = s: the error MRP rotates the pointing axis onto the Sun direction
    # (Schaub & Junkins: sigma = tan(phi/4) e)
    s = np.array([0.3, 0.5, 0.8])
    s /= np.linalg.norm(s)
    sig, phi = sun_pointing_mrp(s, (0, 0, 1))
    assert np.allclose(mrp_to_dcm(sig) @ [0, 0, 1.0], s)
    assert phi == pytest.approx(np.arccos(s[2]))
    assert np.linalg.norm(sig) == pytest.approx(np.tan(phi / 4))
    sig, phi = sun_pointing_mrp([0, 0, -1.0], (0, 0, 1))
    assert phi == pytest.approx(np.pi) and np.linalg.norm(sig) == pytest.approx(1.0)


def test_control_law_inline_deadband_and_saturation():
    I = np.diag([10.5, 8.0, 7.5])
    G = wheel_pyramid()
    Gp = G.T @ np.linalg.inv(G @ G.T)
    h_w = np.array([0.01, -0.02, 0.0, 0.005])
    w = np.array([0.001, -0.002, 0.0015])
    s = np.array([0.2, 0.1, 0.97])
    s /= np.linalg.norm(s)
    K, P = 0.02, 0.3
    u = mrp_control_nb(s, True, w, I, G, h_w, Gp, K, P, np.radians(1), 10.0, np.array([0, 0, 1.0]))
    sig, _ = sun_pointing_mrp(s)
    Lr = -K * sig - P * w + np.cross(w, I @ w + G @ h_w)
    assert np.allclose(-G @ u, Lr, atol=1e-15)
    # inside the deadband only rate damping + gyroscopic terms remain
    s_db = np.array([np.sin(np.radians(0.5)), 0, np.cos(np.radians(0.5))])
    u = mrp_control_nb(s_db, True, w, I, G, h_w, Gp, K, P, np.radians(1), 10.0, np.array([0, 0, 1.0]))
    assert np.allclose(-G @ u, -P * w + np.cross(w, I @ w + G @ h_w), atol=1e-15)
    # saturation at u_max
    u = mrp_control_nb(s, True, w * 1000, I, G, h_w, Gp, K, P, np.radians(1), 0.03, np.array([0, 0, 1.0]))
    assert np.max(np.abs(u)) == pytest.approx(0.03)


def test_torque_free_truth_conserves_angular_momentum():
    # no gravity gradient, no control: the inertial angular momentum
    # H_I = A(q)^T ([I] w + J_s G Omega) is conserved (Euler's equations, Schaub eq. 4.33)
    sc = Scenario(dual_pyramid(), estimator="lsmn", gyro=None, duration_s=600.0, dt_s=0.25,
                  gravity_gradient=False, albedo=False)
    r = simulate(sc, 3)
    scf = Spacecraft()
    I = np.asarray(scf.inertia)
    Hb = r.omega @ I.T + scf.wheel_inertia * r.wheel_speed @ scf.wheel_axes.T
    HI = quat_rotate_inv(r.q, Hb)
    assert np.max(np.linalg.norm(HI - HI[0], axis=1)) < 1e-9 * np.linalg.norm(HI[0])
    # rotational kinetic energy of the rigid body (wheels at rest relative to it: Omega stays
    # at -G^T w + const ~ small) is conserved to RK4 accuracy
    assert np.allclose(np.linalg.norm(r.q, axis=1), 1.0)
    # the simulated Sun direction in body axes is A(q) s_I
    assert np.allclose(quat_rotate_inv(r.q, r.s_true), r.info["sun_I_hat"], atol=1e-12)


def test_seed_reproducible():
    sc = Scenario(dual_pyramid(), estimator="ekf", gyro="tactical", duration_s=120.0)
    a, b = simulate(sc, 5), simulate(sc, 5)
    assert np.array_equal(a.s_hat, b.s_hat) and np.array_equal(a.y, b.y)


def test_controlled_sun_pointing_converges():
    # closed loop with the EKF and a tactical gyro: the +z axis reaches the Sun and stays
    # near it (deadband 1 deg plus estimation error of a few degrees)
    sc = Scenario(dual_pyramid(), estimator="ekf", gyro="tactical", controlled=True,
                  duration_s=1500.0)
    for seed in range(3):
        r = simulate(sc, seed)
        pe = np.degrees(np.arccos(np.clip(r.s_true @ [0, 0, 1.0], -1, 1)))
        late = (r.t > 900) & (r.lit > 0.999)
        assert np.percentile(pe[late], 95) < 8.0
    # the same case uncontrolled keeps tumbling (the pointing error is not small)
    r = simulate(Scenario(dual_pyramid(), estimator="ekf", gyro="tactical", duration_s=1500.0), 0)
    pe = np.degrees(np.arccos(np.clip(r.s_true @ [0, 0, 1.0], -1, 1)))
    assert np.percentile(pe[r.t > 900], 95) > 30.0


def test_settled_mask():
    t = np.arange(10.0)
    lit = np.array([1, 1, 1, 0, 0, 1, 1, 1, 1, 1.0])
    m = settled_mask(t, lit, 2.0)
    assert m.tolist() == [False, False, True, False, False, False, False, True, True, True]


@pytest.mark.slow
def test_tumbling_monte_carlo_dual_pyramid():
    # Acceptance (issue 8): uncontrolled tumbling, dual pyramid, §2.4 dispersions as
    # implemented (Dispersions defaults), built-in zonal albedo, tactical-grade gyro, 30 runs,
    # errors after the first 5 minutes in sunlight.  The thesis's bounds: 5 deg (EKF) and
    # 6 deg (ECKF).  With the filters' albedo model (phi grid filter, the default) the 200-run
    # sets of benchmarks/css.py give EKF 1.73-1.92 / ECKF 1.75-1.91 deg over study seeds 1-3
    # (without the albedo model 5.30 / 5.44 deg at seed 1, which missed the EKF bound), so
    # the thesis bounds are asserted as published.  The single-point methods must be far worse (thesis: above 45 deg; ours
    # ~35-40 deg because of the 0.5 activity threshold shared by all methods).
    spec = StudySpec(n_runs=30, duration_s=1200.0, seed=1)
    ekf = run_case(spec, "ekf", "tactical")
    eckf = run_case(spec, "eckf", "tactical")
    lsmn = run_case(spec, "lsmn", "tactical")
    assert ekf.p99_settled_deg < 5.0
    assert eckf.p99_settled_deg < 6.0
    assert lsmn.p99_settled_deg > 25.0
    assert ekf.p50_settled_deg < 1.5
    # consistency of the Sun direction (2-DOF NEES, chi-square: 95 % of samples below 5.99
    # for a consistent filter).  Without the albedo model the EKF had only 41 % of the
    # samples inside (mean NEES 13: over-confident); with it ~99 % (mean ~0.9: slightly
    # conservative, the albedo-model variance is a bound).  Asserted: not over-confident.
    for c in (ekf, eckf):
        assert c.nees_frac_95 > 0.9
        assert c.nees_mean < 3.0
