"""The O'Keefe (2015) set-up and the thesis-variant estimators/controller against independent
NumPy re-implementations written here (eq. numbers from ../shared/seeds/000_acf2322159507162.txt).
"""

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from lightcurve.css import okeefe2015 as ok
from lightcurve.css.experiments import thesis_css, thesis_filter_params, thesis_scenario
from lightcurve.css.sunline_thesis import (thesis_init_nb, thesis_propagate_nb, thesis_state,
                                           thesis_update_nb)
from lightcurve.css.sensors import normal_to_azel


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0.0]])


def test_table_values_and_wheel_matrix():
    # Table 2.3 and §2.3.3: σ_ωd² = (2/τ) σ_ωr², τ = 1000 s (§2.4)
    sw, sr, sd = ok.gyro_sigmas("intermediate")
    assert sw == pytest.approx(np.radians(1e-4)) and sr == pytest.approx(np.radians(1e-6))
    assert sd == pytest.approx(np.sqrt(2 / 1000.0) * np.radians(1e-6))
    # §2.4 G_s: unit spin axes, rank 3
    G = ok.WHEEL_AXES
    assert np.allclose(np.linalg.norm(G, axis=0), 1.0) and np.linalg.matrix_rank(G) == 3
    css = thesis_css("dual_pyramid")
    assert np.allclose(np.degrees(css.fov_half_angle_rad), 60.0)   # §2.1.3
    # §2.2.1: the +z pyramid cannot see below the x-y plane (structure horizon)
    s = np.array([np.cos(np.radians(-5)), 0.0, np.sin(np.radians(-5))])
    assert css.signals(s)[0] == 0.0
    assert thesis_css("dual_pyramid", 90.0).signals([1, 0, 1e-3])[0] > 0.7


def test_thesis_propagation_matches_exact_rotation_and_riccati():
    # ḋ = −ω×d: RK4 at 10 Hz vs exp(−[ω×]t); EKF covariance with no noise: Φ P Φᵀ (eq. 3.19)
    w = np.radians([1.5, -2.0, 0.7])
    d, P, L, Lam, B, Bnu = thesis_state(8)
    d[:] = [0.3, 0.8, -0.5]
    P[:, :] = np.diag([0.1, 0.2, 0.3])
    prm = thesis_filter_params("ekf", "intermediate")
    d0, P0 = d.copy(), P.copy()
    for _ in range(100):
        thesis_propagate_nb(d, P, L, Lam, B, w, 0.1, prm, 0.0, 0.0)
    Phi = expm(-_skew(w) * 10.0)
    assert np.allclose(d, Phi @ d0, atol=1e-10)
    assert np.allclose(P, Phi @ P0 @ Phi.T, atol=1e-10)


def test_eckf_propagation_matches_augmented_riccati():
    # eq. 3.39 on the augmented covariance P_z = [[P_x, L, Λ], [Lᵀ, B_η, 0], [Λᵀ, 0, B_ν]]
    # with Θ = [[F, S, 0], 0, 0] and Υ Q Υᵀ, integrated by scipy (independent of eq. 3.42)
    N = 8
    prm = thesis_filter_params("eckf", "moderate")
    sig_s, sig_w, sig_wd = 2e-3, prm[3], prm[4]
    w = np.radians([0.4, -1.0, 2.0])
    d, P, L, Lam, B, Bnu = thesis_state(N)
    d[:] = [0.2, -0.4, 1.0]
    rng = np.random.default_rng(1)
    A = rng.normal(size=(3, 3)) * 0.1
    P[:, :] = A @ A.T + 0.01 * np.eye(3)
    L[:, :] = rng.normal(size=(3, 6)) * 1e-4
    Lam[:, :] = rng.normal(size=(3, 4 * N)) * 1e-3
    B[:, :] = np.diag([1e-12] * 3 + [1e-8] * 3)
    n = 3 + 6

    def rhs(_t, y):
        dd = y[:3]
        Pz = y[3:].reshape(n, n)
        F = -_skew(w)
        S = np.hstack([np.eye(3), -_skew(dd)])
        Th = np.zeros((n, n))
        Th[:3, :3] = F
        Th[:3, 3:] = S
        U = np.zeros((n, 9))
        U[:3, :3] = -np.eye(3)
        U[:3, 3:6] = -_skew(dd)
        U[6:9, 6:9] = np.eye(3)   # gyro-bias random walk on the ω_β block of β_η
        Q = np.diag([sig_s ** 2] * 3 + [sig_w ** 2] * 3 + [sig_wd ** 2] * 3)
        dP = Th @ Pz + Pz @ Th.T + U @ Q @ U.T
        return np.concatenate([F @ dd, dP.ravel()])

    Pz0 = np.zeros((n, n))
    Pz0[:3, :3], Pz0[:3, 3:], Pz0[3:, :3], Pz0[3:, 3:] = P, L, L.T, B
    sol = solve_ivp(rhs, (0, 5.0), np.concatenate([d, Pz0.ravel()]), rtol=1e-11, atol=1e-14)
    Pz = sol.y[3:, -1].reshape(n, n)
    Lam0 = Lam.copy()
    for _ in range(50):
        thesis_propagate_nb(d, P, L, Lam, B, w, 0.1, prm, sig_s, sig_w)
    assert np.allclose(d, sol.y[:3, -1], atol=1e-9)
    assert np.allclose(P, Pz[:3, :3], atol=1e-9)
    assert np.allclose(L, Pz[:3, 3:], atol=1e-12)
    assert np.allclose(B, Pz[3:, 3:], atol=1e-15)
    assert np.allclose(Lam, expm(-_skew(w) * 5.0) @ Lam0, atol=1e-10)   # eq. 3.42c


def _setup(kind, y, d_true=None):
    css = thesis_css("dual_pyramid")
    prm = thesis_filter_params(kind, "intermediate")
    st = thesis_state(8)
    az, el = normal_to_azel(css.normals)
    return css, prm, st, np.ascontiguousarray(az), np.ascontiguousarray(el)


def test_ekf_update_matches_numpy_joseph():
    # eq. 3.21-3.24 with H_i = n̂_iᵀ for sensors predicted in view (3.31c), M = |d̂| I (3.31d)
    css, prm, (d, P, L, Lam, B, Bnu), az, el = _setup("ekf", None)
    d[:] = np.array([0.2, 0.1, 1.0]) * 1.2 / np.linalg.norm([0.2, 0.1, 1.0])
    P[:, :] = np.diag([0.02, 0.03, 0.01])
    y = np.array([0.9, 0.8, 0.5, 0.6, 0.0, 0.0, 0.01, 0.0])
    u = d / np.linalg.norm(d)
    cf = np.cos(css.fov_half_angle_rad)
    sel = [i for i in range(8) if css.normals[i] @ u >= cf[i] or y[i] > 0.5 * np.linalg.norm(d)]
    H = css.normals[sel]
    R = np.diag([(np.linalg.norm(d) * 1.84 * (1 if css.normals[i] @ u >= cf[i] else 2.0)) ** 2
                 for i in sel])
    W = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(W)
    nu = y[sel] - H @ d
    d_ref = d + K @ nu
    IKH = np.eye(3) - K @ H
    P_ref = IKH @ P @ IKH.T + K @ R @ K.T
    m, nis = thesis_update_nb(d, P, L, Lam, B, Bnu, y, css.normals, az, el, cf,
                              css.horizon_normals, prm)
    assert m == len(sel)
    assert np.allclose(d, d_ref, atol=1e-12) and np.allclose(P, P_ref, atol=1e-12)
    assert nis == pytest.approx(nu @ np.linalg.solve(W, nu))


def test_eckf_update_equals_schmidt_joseph_on_augmented_state():
    # eq. 3.52 (traditional consider update) = the Joseph update of the augmented covariance
    # with the gain rows of the biases set to zero (eq. 3.50 with K_b = 0)
    css, prm, (d, P, L, Lam, B, Bnu), az, el = _setup("eckf", None)
    # Sun along +z: sensors 1-4 see it 45° off their normals, 15° inside their 60° FOV, far
    # (> γ of §3.2.3 for this small P) from any visibility boundary: no consistency inflation
    y = np.array([0.9, 0.7, 0.95, 0.8, 0.02, 0.0, 0.0, 0.0])
    assert thesis_init_nb(y, css.normals, prm, d, P, L, Lam, B, Bnu)
    d[:] = [0.01, -0.02, 1.2]
    rng = np.random.default_rng(3)
    P[:, :] = np.diag([1e-4, 2e-4, 1.5e-4])
    L[:, :] = rng.normal(size=(3, 6)) * 1e-5
    Lam[:, :] = rng.normal(size=(3, 32)) * 1e-4
    N = 8
    nb = 4 * N
    n = 3 + 6 + nb
    Pz = np.zeros((n, n))
    Pz[:3, :3], Pz[:3, 3:9], Pz[:3, 9:] = P, L, Lam
    Pz[3:9, :3], Pz[9:, :3] = L.T, Lam.T
    Pz[3:9, 3:9] = B
    Pz[9:, 9:] = np.diag(Bnu)
    dd = d.copy()
    nd = np.linalg.norm(dd)
    u = dd / nd
    cf = np.cos(css.fov_half_angle_rad)
    P0 = P.copy()
    m, nis = thesis_update_nb(d, P, L, Lam, B, Bnu, y, css.normals, az, el, cf,
                              css.horizon_normals, prm)
    assert m > 0
    # rebuild Y = [H 0 J] and R exactly as eq. 3.57 (no consistency inflation is active here:
    # checked by comparing with the kernel's own W through the NIS below)
    sel = [i for i in range(N) if css.normals[i] @ u >= cf[i] or y[i] > 0.5 * nd]
    Y = np.zeros((len(sel), n))
    R = np.zeros((len(sel), len(sel)))
    for a, i in enumerate(sel):
        Y[a, :3] = css.normals[i]
        Y[a, 9 + 3 * N + i] = nd
        if css.normals[i] @ u >= cf[i]:
            th, ph = az[i], el[i]
            Y[a, 9 + i] = css.normals[i] @ dd
            Y[a, 9 + N + i] = np.cos(ph) * (-dd[0] * np.sin(th) + dd[1] * np.cos(th))
            Y[a, 9 + 2 * N + i] = (-(dd[0] * np.cos(th) + dd[1] * np.sin(th)) * np.sin(ph)
                                   + dd[2] * np.cos(ph))
        R[a, a] = (nd * 0.05 * (1 if css.normals[i] @ u >= cf[i] else 2.0)) ** 2
    W = Y @ Pz @ Y.T + R
    nu = y[sel] - css.normals[sel] @ dd
    assert len(sel) == 4
    assert nis == pytest.approx(nu @ np.linalg.solve(W, nu), rel=1e-9)
    K = Pz @ Y.T @ np.linalg.inv(W)
    K[3:] = 0.0
    IKY = np.eye(n) - K @ Y
    Pz_post = IKY @ Pz @ IKY.T + K @ R @ K.T
    assert np.allclose(d, dd + K[:3] @ nu, atol=1e-12)
    assert np.allclose(P, Pz_post[:3, :3], atol=1e-12)
    assert np.allclose(L, Pz_post[:3, 3:9], atol=1e-14)
    assert np.allclose(Lam, Pz_post[:3, 9:], atol=1e-13)
    assert np.all(np.linalg.eigvalsh(P) > 0) and np.trace(P) < np.trace(P0)


def test_thesis_control_law_matches_eq_3_64_inline():
    from lightcurve.css.control import sun_pointing_mrp
    from lightcurve.css.truth import _thesis_control_nb

    I = np.diag([10.5, 8.0, 7.5])
    G = ok.WHEEL_AXES
    Gp = G.T @ np.linalg.inv(G @ G.T)
    w = np.radians([0.5, -0.3, 0.2])
    Om = np.array([10.0, -5.0, 3.0, 0.0])
    h_abs = 0.001 * (G.T @ w + Om)
    s = np.array([0.3, 0.2, 0.93])
    s /= np.linalg.norm(s)
    zint = np.array([1e-4, -2e-4, 5e-5])
    dw0 = np.radians([1.0, 1.0, -1.0])
    gains = np.array([0.041, 0.5, 0.001, np.radians(1.0)])
    z0 = zint.copy()
    u = _thesis_control_nb(s, True, w, I, G, Gp, h_abs, zint, dw0, gains, 10.0,
                           np.array([0, 0, 1.0]), 0.1)
    sig, _ = sun_pointing_mrp(s)
    z = z0 + 0.041 * sig * 0.1 + I @ (w - dw0)       # z = K∫σ dt + [I](Δω − Δω₀)
    H = I @ w + G @ h_abs
    rhs = 0.041 * sig + 0.5 * w + 0.5 * 0.001 * z + np.cross(0.001 * z, H)   # eq. 3.64
    assert np.allclose(G @ u, rhs, atol=1e-14)
    assert np.allclose(zint, z0 + 0.041 * sig * 0.1)
    # inside the 1° deadband σ = 0 (§3.3.2), rate damping stays
    s_db = np.array([np.sin(np.radians(0.5)), 0, np.cos(np.radians(0.5))])
    zint = z0.copy()
    u = _thesis_control_nb(s_db, True, w, I, G, Gp, h_abs, zint, dw0, gains, 10.0,
                           np.array([0, 0, 1.0]), 0.1)
    z = z0 + I @ (w - dw0)
    assert np.allclose(G @ u, 0.5 * w + 0.0005 * z + np.cross(0.001 * z, H), atol=1e-14)


def _short(est, gyro, controlled=False):
    return thesis_scenario("dual_pyramid", est, gyro=gyro, controlled=controlled,
                           duration_s=120.0, albedo="builtin", perturbations=False)


def test_truth_is_the_same_with_and_without_gyro():
    # the no-gyro defect: every row of a study flies the same spacecraft (common random
    # numbers) — the truth and the CSS outputs do not depend on the gyro option
    from lightcurve.css.truth import simulate_css

    a = simulate_css(_short("wavg", "intermediate"), np.random.SeedSequence([7, 1]))
    b = simulate_css(_short("wavg", None), np.random.SeedSequence([7, 1]))
    c = simulate_css(_short("ekf", "low"), np.random.SeedSequence([7, 1]))
    assert np.array_equal(a.q, b.q) and np.array_equal(a.y, b.y) and np.array_equal(a.q, c.q)
    # §2.4 dispersions: rates uniform within ±2°/s per axis; common scale 1..1.5
    assert np.all(np.abs(np.degrees(a.info["omega0_rad_s"])) <= 2.0)
    assert 1.0 <= a.info["css_scale_common"] <= 1.5
    assert a.t[1] - a.t[0] == 0.5   # CSS at 2 Hz


def test_thesis_ekf_converges_tumbling_without_albedo():
    # one 20-minute tumbling run without albedo or misalignment, started in sunlight: after
    # 850 s (the Sun sets at ≈1050 s in this run) the EKF error is below 3° (thesis: 1.75° p99 with every error source on)
    from lightcurve.css.truth import simulate_css

    sc = thesis_scenario("dual_pyramid", "ekf", duration_s=1200.0, albedo="none",
                         perturbations=False, sim={"misalignment_sigma_deg": 0.0})
    sc.start_sunlit = True
    r = simulate_css(sc, np.random.SeedSequence([1, 0]))
    m = (r.direct > 0) & (r.t > 850)
    assert m.sum() > 200
    assert np.percentile(r.error_deg[m], 99) < 3.0


def test_perturbed_orbit_stays_circular_400km():
    # J2-J6 + drag + SRP (§2.4): a 100-minute arc stays within a few km of 400 km altitude
    from lightcurve.css.truth import simulate_css

    sc = thesis_scenario("dual_pyramid", "wavg", duration_s=600.0, albedo="none")
    r = simulate_css(sc, np.random.SeedSequence([2, 0]))
    h = np.linalg.norm(r.info["r_I_m"], axis=1) - 6378137.0
    assert np.all(np.abs(h - 400e3) < 25e3)   # J2 alone moves a polar orbit by ~±11 km
    assert np.degrees(r.info["raan_rad"]) == pytest.approx(60.0)


def test_reproduction_css_section(tmp_path):
    from lightcurve.studies.reproduction import css_section, write_reproduction

    d = tmp_path / "s"
    d.mkdir()
    cases = [{"estimator": "ekf", "variant": "thesis", "gyro": "intermediate", "runs": 5,
              "p99_level_deg": 2.0, "p99_pooled_deg": 2.5, "thesis_p99_deg": 1.75,
              "ratio_to_thesis": 2.0 / 1.75},
             {"estimator": "eckf", "variant": "thesis", "gyro": "intermediate", "runs": 5,
              "p99_level_deg": 3.5, "thesis_p99_deg": 3.1, "ratio_to_thesis": 3.5 / 3.1}]
    (d / "summary.json").write_text(json.dumps({"experiment": "fig3_09", "runs": 5,
                                                "albedo": "toms", "failures": 0,
                                                "verdict": "v", "cases": cases}))
    txt = css_section([d])
    assert "| EKF | intermediate | 1.75 | 2.00 / 2.50 | 1.14 |" in txt
    assert "ECKF ≈ 1.8× EKF" in txt and "1.75×" in txt and "**agrees**" in txt
    out = write_reproduction(tmp_path / "r.md", [txt])
    assert out.read_text().startswith("# Reproduction")


def test_albedo_coefficient_covariance_matches_brute_force():
    # eq. 4.30b: Σ_j σ_j² A_j² w_j² c_ij c_kj over all sunlit, visible cells in both FOVs,
    # re-computed here cell by cell from the map (no window)
    from lightcurve.css.albedo import (AlbedoCells, albedo_coefficient_cov_nb,
                                       builtin_albedo_map, cell_areas_m2)

    m = builtin_albedo_map(10.0)
    cells = AlbedoCells.from_map(m)
    std = 0.5 * m.values
    sig_area = (cell_areas_m2(m.lat_edges_rad, m.lon_edges_rad) * std).reshape(-1)
    rng = np.random.default_rng(2)
    up = np.array([0.3, -0.5, 0.81])
    up /= np.linalg.norm(up)
    r = 6778e3 * up
    s_E = up + np.array([0.4, 0.2, 0.0])
    s_E /= np.linalg.norm(s_E)
    nE = rng.normal(size=(4, 3)) - 2 * up
    nE /= np.linalg.norm(nE, axis=1)[:, None]
    cf = np.full(4, np.cos(np.radians(60)))
    hE = np.zeros((4, 3))
    Ra = albedo_coefficient_cov_nb(*cells.args()[:3], np.ascontiguousarray(sig_area),
                                   *cells.args()[3:], r, s_E, nE, cf, hE)
    ref = np.zeros((4, 4))
    for j in range(cells.centers_m.shape[0]):
        c, n = cells.centers_m[j], cells.normals[j]
        d = r - c
        dist = np.linalg.norm(d)
        cs, cv = n @ s_E, n @ d / dist
        if cs <= 0 or cv <= 0:
            continue
        w = sig_area[j] * cs * cv / (np.pi * dist ** 2)
        cc = nE @ (-d / dist)
        cc = np.where(cc >= cf, cc, 0.0)
        ref += np.outer(w * cc, w * cc)
    assert np.abs(ref).max() > 0
    assert np.allclose(Ra, ref, rtol=1e-10, atol=1e-18)


def test_thesis_calibration_parameters_from_the_text():
    from lightcurve.css.calibration import CalibrationParams

    p = CalibrationParams.thesis_full("5x5")
    assert p.thesis and p.sigma_css == pytest.approx(0.15)   # 0.05 + 0.1 (§4.4.3)
    assert p.meas_floor == pytest.approx(0.1)                 # 2 σ_V (§4.2)
    assert p.init_threshold == 0.4                             # §5.2
    assert 3 * p.sigma_scale0 == pytest.approx(0.9)            # tables 4.1-4.3 initial 3σ
    assert 3 * np.degrees(p.sigma_mis0_rad) == pytest.approx(3.0)
    r = CalibrationParams.thesis_reduced()
    assert not r.use_albedo and r.sigma_css == 0.05 and r.consider_sigma == 0.1


def test_calibration_timings_count_the_calls_of_table_4_4():
    """O'Keefe §4.4.3: in 3460 s "the propagation update is called 34601 times and the
    estimation update 6921 times" (10 Hz gyro, 2 Hz CSS). Over 50 s of a §4.4 case the timed
    loop records 10 propagation steps per second and one update per 2 Hz sample (101),
    positive and finite, and timing does not change the estimates."""
    from lightcurve.css.calibration import (run_calibration, simulate_thesis_calibration_case,
                                            thesis_filter_setup)

    case = simulate_thesis_calibration_case(3, duration_s=50.0, albedo="builtin")
    prm, alb = thesis_filter_setup("reduced")

    def run(tm=None):
        return run_calibration(case.css_nominal, case.t, case.Y, case.gyro, case.sun_N,
                               case.lit, case.r_I_m, case.epoch_utc, params=prm, albedo=alb,
                               q_star=case.q_star, star_valid=case.star_valid, timings=tm)

    tm = {}
    timed, plain = run(tm), run()
    assert tm["update_us"].size == 101 and tm["propagation_us"].size == 500
    assert np.all(np.isfinite(tm["update_us"])) and np.all(tm["update_us"] > 0)
    assert np.all(tm["propagation_us"] > 0)
    assert np.array_equal(timed.x, plain.x) and np.array_equal(timed.P_end, plain.P_end)
def test_thesis_shadow_decision_and_no_update_on_a_fading_sun():
    # eq. 3.1/3.31: no direct-Sun model (B ∈ S) when no output reaches 50 % of the expected
    # maximum |d̂| (§3.2.1.2's strong-measurement level; with the 60° FOV of §2.1.3 a directly
    # lit sensor reads at least cos 60° = 50 %): the penumbra's fading Sun must not drag d̂.
    from lightcurve.css.sunline_thesis import thesis_sunlit_nb

    for kind in ("ekf", "eckf"):
        css, prm, (d, P, L, Lam, B, Bnu), az, el = _setup(kind, None)
        assert prm[8] == pytest.approx(0.5) and prm[17] == pytest.approx(0.5)
        s = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
        C = 1.3
        y_full = C * np.clip(css.normals @ s, 0.0, None) * (css.normals @ s
                                                             >= np.cos(css.fov_half_angle_rad))
        assert thesis_init_nb(y_full, css.normals, prm, d, P, L, Lam, B, Bnu)
        d[:] = C * s
        P[:, :] = np.eye(3) * 1e-3
        cf = np.cos(css.fov_half_angle_rad)
        # plain rule, written out: sunlit ⇔ max y ≥ 0.5 and (not started or max y ≥ 0.5 |d̂|)
        for lit in (1.0, 0.8, 0.45, 0.2, 0.0):
            y = lit * y_full
            ref = y.max() >= 0.5 and y.max() >= 0.5 * np.linalg.norm(d)
            assert thesis_sunlit_nb(y, d, prm, True) == ref
            assert thesis_sunlit_nb(y, d, prm, False) == (y.max() >= 0.5)
        d0, P0 = d.copy(), P.copy()
        y = 0.45 * y_full    # penumbra: max output 0.45·1.3·cos(≈17°) < 0.5·1.3
        assert y.max() < 0.5 * np.linalg.norm(d)
        m, nis = thesis_update_nb(d, P, L, Lam, B, Bnu, y, css.normals, az, el, cf,
                                  css.horizon_normals, prm)
        assert m == 0 and np.isnan(nis)
        assert np.array_equal(d, d0) and np.array_equal(P, P0)
        # the same fading Sun with the rule off (the earlier absolute level only) is processed
        # and pulls |d̂| down (the run-away of the penumbra)
        prm_off = prm.copy()
        prm_off[8], prm_off[17] = 0.25, 0.0
        m, nis = thesis_update_nb(d, P, L, Lam, B, Bnu, y, css.normals, az, el, cf,
                                  css.horizon_normals, prm_off)
        assert m > 0 and np.linalg.norm(d) < np.linalg.norm(d0)


def test_eckf_measurement_bias_jacobian_matches_finite_differences():
    # eq. 3.57f against central differences of the measurement model eq. 3.1 (as in §3.2.2.2)
    # h = C_κ n(θ+θ_β, φ+φ_β)ᵀ d + |d| C_κ V_αβ at Ĉ_κ = 1, θ̂_β = φ̂_β = V̂_αβ = 0: one sensor,
    # one bias with a prior at a time, P_x ≈ 0 and Λ = 0, so the innovation variance of
    # eq. 3.47 is W = J_p² σ_p² + |d|² σ_V² and J_p is read back from the kernel's NIS.
    th, ph = np.radians(30.0), np.radians(20.0)

    def nvec(t, p):
        return np.array([np.cos(p) * np.cos(t), np.cos(p) * np.sin(t), np.sin(p)])

    n = nvec(th, ph)
    a = np.cross(n, [0.3, -0.5, 0.8])     # a generic direction: every derivative non-zero
    a /= np.linalg.norm(a)
    ang = np.radians(25.0)          # 25° inside the 60° FOV: no §3.2.3 inflation
    d0 = 1.2 * (np.cos(ang) * n + np.sin(ang) * np.cross(a, n))

    def h(C=1.0, dth=0.0, dph=0.0, V=0.0):
        return C * nvec(th + dth, ph + dph) @ d0 + np.linalg.norm(d0) * C * V

    eps = 1e-6
    fd = [(h(C=1 + eps) - h(C=1 - eps)) / (2 * eps), (h(dth=eps) - h(dth=-eps)) / (2 * eps),
          (h(dph=eps) - h(dph=-eps)) / (2 * eps), (h(V=eps) - h(V=-eps)) / (2 * eps)]
    prm = thesis_filter_params("eckf", "intermediate")
    sig_v = prm[1]
    normals = n[None, :].copy()
    for p in range(4):
        d = d0.copy()
        P = np.eye(3) * 1e-20
        L, Lam, B = np.zeros((3, 6)), np.zeros((3, 4)), np.zeros((6, 6))
        Bnu = np.zeros(4)
        sig_p = 0.3
        Bnu[p] = sig_p ** 2
        y = np.array([h() + 0.2])
        m, nis = thesis_update_nb(d, P, L, Lam, B, Bnu, y, normals, np.array([th]),
                                  np.array([ph]), np.array([0.5]), np.zeros((1, 3)), prm)
        assert m == 1
        W = 0.2 ** 2 / nis
        Jp2 = (W - (np.linalg.norm(d0) * sig_v) ** 2) / sig_p ** 2
        assert abs(fd[p]) > 0.05
        assert np.sqrt(Jp2) == pytest.approx(abs(fd[p]), rel=1e-6)
        # the sign, through the cross term H Λ Jᵀ + J Λᵀ Hᵀ of eq. 3.47 (Λ column p = λ n)
        lam = 1e-3
        d = d0.copy()
        P = np.eye(3) * 1e-20
        Lam = np.zeros((3, 4))
        Lam[:, p] = lam * n
        m, nis2 = thesis_update_nb(d, P, np.zeros((3, 6)), Lam, np.zeros((6, 6)), Bnu.copy(), y,
                                   normals, np.array([th]), np.array([ph]), np.array([0.5]),
                                   np.zeros((1, 3)), prm)
        Jp = (0.2 ** 2 / nis2 - W) / (2 * lam)
        assert Jp == pytest.approx(fd[p], rel=1e-5)


def test_thesis_truth_shadow_is_binary_as_eq_2_21():
    # eq. 2.21: V_d = V_α = 0 "if B ∈ S" — no partial Sun; the conical model (user default)
    # has a penumbra of a few seconds at 400 km; both agree outside it
    from lightcurve.css.truth import simulate_css

    kw = dict(duration_s=6000.0, albedo="none", perturbations=False)   # > one orbit
    sc_t = thesis_scenario("dual_pyramid", "wavg", **kw)
    assert sc_t.shadow_model == ok.TRUTH_SHADOW_MODEL == "cylindrical"
    sc_c = thesis_scenario("dual_pyramid", "wavg", sim={"shadow_model": "conical"}, **kw)
    rt = simulate_css(sc_t, np.random.default_rng([5, 1]))
    rc = simulate_css(sc_c, np.random.default_rng([5, 1]))
    assert set(np.unique(rt.lit)) == {0.0, 1.0}
    pen = (rc.lit > 0) & (rc.lit < 1)
    assert 2 <= pen.sum() <= 40        # a few seconds of penumbra at 2 Hz
    assert np.all((rc.lit[~pen] > 0.5) == (rt.lit[~pen] > 0.5))
    # no direct Sun on any sensor while B ∈ S
    assert np.all(rt.direct[rt.lit == 0] == 0)
    with pytest.raises(ValueError, match="shadow_model"):
        thesis_scenario("dual_pyramid", "wavg", sim={"shadow_model": "flat"}, **kw)


def test_thesis_p99_bounds_from_the_text():
    # §3.3.1: single-point errors "above 45°" (a lower bound); §3.3.2 (fig. 3.13): "within 25°"
    # (an upper bound); the EKF's 1.75° (fig. 3.9) a level compared within ±25 %
    from lightcurve.css.okeefe2015 import thesis_p99_agrees, thesis_p99_bound

    assert thesis_p99_bound("fig3_09", "wavg") == "lower"
    assert thesis_p99_bound("fig3_13", "eckf") == "upper"
    assert thesis_p99_bound("fig3_09", "ekf") is None
    assert thesis_p99_agrees("fig3_09", "wavg", 50.0) and not thesis_p99_agrees("fig3_09", "wavg", 30.0)
    assert thesis_p99_agrees("fig3_13", "ekf", 8.0) and not thesis_p99_agrees("fig3_13", "ekf", 26.0)
    assert thesis_p99_agrees("fig3_09", "ekf", 2.1) and not thesis_p99_agrees("fig3_09", "ekf", 2.3)


def _summary(d, experiment, cases, runs=5):
    d.mkdir()
    (d / "summary.json").write_text(json.dumps({"experiment": experiment, "runs": runs,
                                                "albedo": "toms", "failures": 0,
                                                "verdict": "v", "cases": cases}))
    return d


def _c(est, p99, th=None, above15_s=None, runs=5, gyro="intermediate"):
    c = {"estimator": est, "variant": "thesis", "gyro": gyro, "runs": runs,
         "p99_level_deg": p99, "p99_pooled_deg": p99, "thesis_p99_deg": th}
    if th is not None:
        c["ratio_to_thesis"] = p99 / th
    if above15_s is not None:
        c["above15_s_per_orbit"] = {"median": above15_s / 2, "p99": above15_s, "max": above15_s}
    return c


def test_reproduction_bounds_are_not_ratios(tmp_path):
    # a bound is printed as one ("≤ 25", "> 45") and gets no ratio; the study verdict reads it
    # the same way
    from lightcurve.css.study import StudySpec, _verdict
    from lightcurve.studies.reproduction import css_section

    d13 = _summary(tmp_path / "c", "fig3_13", [_c("ekf", 8.0, 25.0)])
    d09 = _summary(tmp_path / "t", "fig3_09", [_c("ekf", 1.8, 1.75), _c("wavg", 40.0, 45.0)])
    txt = css_section([d13, d09])
    assert "| EKF | intermediate | ≤ 25 | 8.00 / 8.00 | – |" in txt
    assert "| WAVG | intermediate | > 45 | 40.00 / 40.00 | – |" in txt
    assert "| EKF | intermediate | 1.75 | 1.80 / 1.80 | 1.03 |" in txt
    v = _verdict(StudySpec(experiment="fig3_13"), [_c("ekf", 8.0, 25.0)])
    assert v["level"] == "ok" and "≤ 25°" in v["text"]
    v = _verdict(StudySpec(experiment="fig3_13"), [_c("ekf", 30.0, 25.0)])
    assert v["level"] == "warn"


def test_reproduction_time_above_15_claims(tmp_path):
    # fig. 3.12 (§3.3.2): EKF/ECKF least time above 15° (2 min), WAVG least of the single-point
    # estimators (14 min), all below 17 min; §3.3.3: every gyro-less EKF run below ≈ 5 min
    from lightcurve.studies.reproduction import css_section

    d11 = _summary(tmp_path / "a", "fig3_11", [
        _c("ekf", 3.0, 4.0, 60.0, runs=200), _c("eckf", 5.0, 6.0, 90.0, runs=200),
        _c("wavg", 8.0, None, 600.0, runs=200), _c("lsmn", 20.0, None, 1200.0, runs=200),
        _c("wlsmn", 10.0, None, 1100.0, runs=200)], runs=200)
    d15 = _summary(tmp_path / "b", "fig3_15", [_c("ekf", 9.0, None, 8 * 60.0),
                                               _c("eckf", 9.0, None, 9 * 60.0)])
    lines = css_section([d11, d15]).splitlines()

    def line(start):
        return next(x for x in lines if x.startswith(start))

    assert "**agrees**" in line("- Controlled dual pyramid: EKF and ECKF spend the least")
    assert "indicative" not in line("- Controlled dual pyramid: EKF and ECKF spend the least")
    assert "**agrees**" in line("- Controlled dual pyramid: WAVG the least")
    assert "at most 20.0 min — **disagrees**" in line("- Controlled dual pyramid: every")
    assert "at most 8.0 min — **disagrees** (5 runs per case: indicative)" in line(
        "- Without a gyro, every EKF run")
    assert "**agrees**" in line("- Without a gyro, the ECKF slightly more")
    # an ablation of the same experiment is marked by the same rule on the same line; its
    # gyro-less overrides are stated in its section
    da = tmp_path / "abl"
    da.mkdir()
    (da / "summary.json").write_text(json.dumps({
        "study": "ablation-fig3_15-x", "experiment": "fig3_15", "runs": 120, "albedo": "toms",
        "failures": 0, "verdict": "v", "gyroless": {"lowpass_hz": 0.1},
        "cases": [_c("ekf", 9.0, None, 2.5 * 60.0, runs=120)]}))
    txt = css_section([d11, d15, da])
    gl = next(x for x in txt.splitlines() if x.startswith("- Without a gyro, every EKF run"))
    assert gl.endswith("; ablation `ablation-fig3_15-x`: at most 2.5 min — **agrees**.")
    assert "thesis-variant gyro-less overrides `lowpass_hz = 0.1`" in txt


def test_reproduction_ablation_states_its_switch(tmp_path):
    # an ablation study is listed under its name with the change it makes
    from lightcurve.studies.reproduction import css_section

    d = tmp_path / "a"
    d.mkdir()
    (d / "summary.json").write_text(json.dumps({
        "study": "ablation-fig3_09-x", "experiment": "fig3_09", "runs": 7, "albedo": "toms",
        "failures": 0, "verdict": "v", "thesis_filter": {"sigma_valpha": 0.2},
        "cases": [_c("eckf", 4.0, 3.1, runs=7)]}))
    txt = css_section([d])
    assert "#### ablation-fig3_09-x" in txt
    assert "7 runs per case of experiment `fig3_09`, truth albedo `toms`, thesis-filter " \
           "overrides `sigma_valpha = 0.2`." in txt
    assert "### Fig. 3.9 — tumbling, dual pyramid (§3.3.1)\n\nNot run yet." in txt


def test_reproduction_cube_single_point_claim(tmp_path):
    # §3.3.1 (fig. 3.10): "the angular error in the three single-point methods are all the same
    # due to the orthogonality of the measurements"
    from lightcurve.studies.reproduction import css_section

    d = _summary(tmp_path / "c", "fig3_10", [_c("wavg", 50.0), _c("lsmn", 60.0),
                                             _c("wlsmn", 50.5)])
    line = next(x for x in css_section([d]).splitlines() if x.startswith("- Cube (fig. 3.10"))
    assert "WAVG 50.0°, LSMN 60.0°, WLSMN 50.5° — **disagrees**" in line


def test_reproduction_cli_counts_css_outputs(tmp_path, capsys):
    from lightcurve.cli import main

    d = _summary(tmp_path / "c", "fig3_10", [_c("ekf", 2.2, 2.0)])
    out = tmp_path / "r.md"
    assert main(["reproduction", "--css", str(d), "-o", str(out)]) == 0
    assert "(0 Bernard and 1 CSS study output(s) read)" in capsys.readouterr().out
    assert "| EKF | intermediate | 2 | 2.20 / 2.20 | 1.10 |" in out.read_text()
