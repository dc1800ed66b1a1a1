"""Models and kernels of the attitude filters, each against an independent computation."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from transition_oracle import discretize, error_F

from lightcurve import rotations as rot
from lightcurve.core import dynamics as CD
from lightcurve.core import particles as CP
from lightcurve.core.rotations import rotvec2q_xyz
from lightcurve.filters import _bpf_kernels as BK
from lightcurve.filters._common import apply_grp, grp_rel
from lightcurve.filters.models import ControlledDynamics, MagnitudeModel, UncontrolledDynamics
from lightcurve.photometry import apparent_magnitude, load_shape


def _rand_q(rng, n):
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_magnitude_model_matches_photometry(curve):
    # oracle: lightcurve.photometry.apparent_magnitude (numpy object layer + its own kernel)
    shape = load_shape("cube_1u_mixed")
    m = MagnitudeModel(shape, curve)
    rng = np.random.default_rng(3)
    Q = _rand_q(rng, 64)
    for k in (0, 17, 59):
        ours = m.predict_q(Q, k)
        ref = apparent_magnitude(shape, Q[None], curve.obj_to_sun_unit[k:k + 1],
                                 curve.obj_to_obs_unit[k:k + 1], curve.range_obs_m[k:k + 1],
                                 curve.range_sun_m[k:k + 1])[0]
        fin = np.isfinite(ref)
        assert np.array_equal(fin, np.isfinite(ours))
        np.testing.assert_allclose(ours[fin], ref[fin], rtol=0, atol=1e-10)
    # the truth attitude reproduces the noise-free magnitudes stored in the curve
    tm = np.array([m.predict_q(curve.truth_q[k], k)[0] for k in range(len(curve))])
    np.testing.assert_allclose(tm, curve.truth_mag, atol=1e-10)


def test_measurement_jacobian_analytic_vs_central_difference(curve):
    # analytic photometry partial (Bernard eq. 8.x, consistent form) vs central differences of
    # m(exp(δθ) ⊗ q̂) with step 1e-6 rad
    m = MagnitudeModel(load_shape("cube_1u_mixed"), curve)
    for k in (3, 30):
        q = curve.truth_q[k]
        Ha = m.jacobian_theta(q, k, method="analytic")
        Hn = m.jacobian_theta(q, k, method="numeric", h=1e-6)
        np.testing.assert_allclose(Ha, Hn, rtol=1e-5, atol=1e-6 * np.abs(Hn).max())
        assert np.abs(Ha).max() > 0.1  # the magnitude does depend on attitude (mag/rad)


def test_controlled_transition_closed_form():
    # Φθθ = exp(−[ω×]Δt) = A(rotvec ωΔt) (Bernard eq. 7.24 integrated exactly),
    # Φθω = ∫₀^Δt exp(−[ω×]s) ds (numerical quadrature), Φωω = I
    w = np.radians([2.0, 1.0, 3.6])
    dt = 5.0
    Phi, Qd = ControlledDynamics().transition(w, dt)
    np.testing.assert_allclose(Phi[:3, :3], rot.rotvec_to_dcm(w * dt), atol=1e-12)
    s = np.linspace(0, dt, 2001)
    integrand = np.array([rot.rotvec_to_dcm(w * si) for si in s])
    np.testing.assert_allclose(Phi[:3, 3:], np.trapezoid(integrand, s, axis=0), atol=1e-6)
    np.testing.assert_allclose(Phi[3:, 3:], np.eye(3), atol=1e-14)
    assert np.all(Qd == 0)
    # the Van Loan path (taken with pseudo-noise) gives the same Φ
    Phi2, Qd2 = ControlledDynamics(pseudo_noise=1e-12).transition(w, dt)
    np.testing.assert_allclose(Phi2, Phi, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(Qd2) > -1e-20) and Qd2[5, 5] > 0


def test_van_loan_matches_continuous_white_noise():
    # For F = 0 on a [θ, ω] double integrator, Van Loan gives σ²[[Δt³/3, Δt²/2],[Δt²/2, Δt]]
    F = error_F(np.zeros(3))
    Qc = np.zeros((6, 6))
    Qc[3:, 3:] = 2.5 * np.eye(3)
    dt = 3.0
    _, Qd = discretize(F, Qc, dt)
    ref = 2.5 * np.kron(np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]), np.eye(3))
    np.testing.assert_allclose(Qd, ref, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("kind", ["controlled", "uncontrolled"])
def test_error_transition_vs_nonlinear_propagation(kind):
    # first-order check of Φ: perturb the state by δx = ε e_j, propagate the nonlinear model,
    # read the error back (rotation vector of q ⊗ q̂⁻¹, ω − ω̂) and compare with Φ δx
    J = np.diag([0.02, 0.03, 0.05])
    dyn = ControlledDynamics() if kind == "controlled" else UncontrolledDynamics(J, substep_s=0.05)
    q = rot.euler321_to_quat(np.radians([10.0, -20.0, 30.0]))
    w = np.radians([2.0, 1.0, 3.6])
    dt = 5.0
    Phi, _ = dyn.transition(w, dt)
    q1, w1 = dyn.propagate(q[None], w[None], dt)
    eps = 1e-6
    cols = []
    for j in range(6):
        cs = []
        for sgn in (1, -1):
            dx = np.zeros(6)
            dx[j] = sgn * eps
            qp = rot.quat_mult(rot.rotvec_to_quat(dx[:3]), q)
            qq, ww = dyn.propagate(qp[None], (w + dx[3:])[None], dt)
            cs.append(np.concatenate([rot.attitude_error_rotvec(qq[0], q1[0]), ww[0] - w1[0]]))
        cols.append((cs[0] - cs[1]) / (2 * eps))
    Phi_fd = np.stack(cols, axis=1)
    # the uncontrolled Φ is a product of exp(F(ω_mid) h) over 0.05 s sub-steps: O(h²)
    tol = 1e-6 if kind == "controlled" else 1e-4
    np.testing.assert_allclose(Phi, Phi_fd, atol=tol)


def test_kernels_against_numpy_rotations():
    rng = np.random.default_rng(5)
    Q = _rand_q(rng, 50)
    W = rng.standard_normal((50, 3)) * 0.1
    Qc = Q.copy()
    CD.const_rate_batch_nb(Qc, W.copy(), 2.5)
    ref = rot.quat_mult(rot.rotvec_to_quat(W * 2.5), Q)
    np.testing.assert_allclose(Qc, ref, atol=1e-14)
    # GRP chart round trip and agreement with rotations.quat_to_grp (a = 1, f = 4)
    qref = Q[0]
    P = grp_rel(Q, qref)
    dq = rot.quat_normalize(rot.quat_mult(Q, rot.quat_conj(qref)[None]))
    np.testing.assert_allclose(P, rot.quat_to_grp(dq), atol=1e-12)
    back = apply_grp(P, qref)
    np.testing.assert_allclose(np.abs(np.sum(back * Q, axis=1)), 1.0, atol=1e-12)


def test_rk4_kernel_against_solve_ivp():
    # torque-free Euler equations (Bernard eq. 4.12–4.13): RK4 kernel vs DOP853 at 1e-12
    J = np.diag([0.02, 0.03, 0.05])
    Ji = np.linalg.inv(J)
    q0 = rot.euler321_to_quat(np.radians([5.0, 10.0, -15.0]))
    w0 = np.radians([3.0, -2.0, 4.0])
    Q = q0[None].copy()
    W = w0[None].copy()
    CD.rk4_propagate_nb(Q, W, J, Ji, 20.0 / 400, 400)

    def f(t, x):
        q, w = x[:4], x[4:]
        qd = 0.5 * rot.quat_mult(np.concatenate([[0.0], w]), q)
        return np.concatenate([qd, Ji @ (-np.cross(w, J @ w))])

    sol = solve_ivp(f, (0, 20.0), np.concatenate([q0, w0]), method="DOP853", rtol=1e-12,
                    atol=1e-12)
    np.testing.assert_allclose(W[0], sol.y[4:, -1], atol=1e-9)
    np.testing.assert_allclose(Q[0], sol.y[:4, -1] / np.linalg.norm(sol.y[:4, -1]), atol=1e-9)


def test_bpf_fused_kernel_equals_separate_steps(curve):
    # bpf_predict_nb (propagate + noise + ζ + magnitude) vs the same steps done separately
    m = MagnitudeModel(load_shape("cube_1u_mixed"), curve)
    rng = np.random.default_rng(8)
    N = 200
    Q = _rand_q(rng, N)
    W = rng.standard_normal((N, 3)) * 0.05
    noise = rng.standard_normal((N, 6)) * 1e-3
    zeta = rng.standard_normal((N, 3)) * 2e-3
    out = np.empty(N)
    Q1, W1 = Q.copy(), W.copy()
    n, a, ids, p = m._karrs
    k = 7
    L = np.tril(rng.standard_normal((6, 6))) * 0.5
    BK.bpf_predict_nb(Q1, W1, 5.0, 0, np.eye(3), np.eye(3), 1, noise, L, zeta, m.s_eci[k],
                     m.o_eci[k], n, a, ids, p, float(m.offset[k]), out, np.empty((0, 4)), 0,
                     np.empty(0))
    # exp(ζ) formed and kept (dq_mode 1), then read back (2): the same numbers, bit for bit
    dq = np.empty((N, 4))
    for mode in (1, 2):
        Q3, W3, out3 = Q.copy(), W.copy(), np.empty(N)
        BK.bpf_predict_nb(Q3, W3, 5.0, 0, np.eye(3), np.eye(3), 1, noise, L, zeta, m.s_eci[k],
                         m.o_eci[k], n, a, ids, p, float(m.offset[k]), out3, dq, mode,
                         np.empty(0))
        assert np.array_equal(Q3, Q1) and np.array_equal(W3, W1)
        assert np.array_equal(out3, out)
    np.testing.assert_allclose(dq, rot.rotvec_to_quat(zeta), atol=1e-15)
    noise = noise @ L.T   # the kernel applies the sample L · z_i
    Q2 = rot.quat_mult(rot.rotvec_to_quat(W * 5.0), Q)
    Q2 = rot.quat_mult(rot.rotvec_to_quat(noise[:, :3]), Q2)
    np.testing.assert_allclose(Q1, Q2, atol=1e-13)
    np.testing.assert_allclose(W1, W + noise[:, 3:], atol=1e-15)
    ref = m.predict_q(rot.quat_mult(rot.rotvec_to_quat(zeta), Q2), k)
    fin = np.isfinite(ref)
    np.testing.assert_allclose(out[fin], ref[fin], atol=1e-10)
    assert np.array_equal(np.isfinite(out), fin)


@numba.njit
def _predict_rows(Q, W, dt, mode, J, Ji, nsub, noise, Lnoise, zeta, s, o, normals, areas, ids,
                  params, offset, m_out):
    """The prediction particle by particle through the row function (the CUDA kernel's)."""
    N = Q.shape[0]
    Fr = np.zeros(normals.shape[0])
    predict = not np.isnan(s[0])
    hI = (0.0, 0.0, 0.0)
    cI = -1.0
    if predict:
        hI, cI = BK.flux_invariants(s, o, ids, params, Fr)
    for i in range(N):
        BK.predict_row(i, Q, W, dt, mode, dt / max(nsub, 1), nsub, CD.mat9(J), CD.mat9(Ji), noise,
                       Lnoise, noise.shape[0] == N, zeta, zeta.shape[0] == N, predict, s, o, hI,
                       cI, Fr, normals, areas, ids, params, offset, m_out)


def test_vectorised_prediction_is_the_row_function_bit_for_bit(curve):
    # the block kernel reorders the work (libm calls in their own passes, the rest vectorised
    # across particles) but must keep every particle's operations: equal to the bit to the row
    # function, for every branch (rate step or RK4, process noise, jitter formed / kept / read,
    # dt = 0, no prediction, Cook–Torrance in both forms, Lambert, Phong, a skipped facet) and
    # for a cloud that ends in a partial block of a partial chunk
    from lightcurve.core.photometry import COOK_TORRANCE_THESIS, LAMBERT, PHONG

    m = MagnitudeModel(load_shape("cube_1u_mixed"), curve)
    rng = np.random.default_rng(21)
    N = 2 * 2048 + 77
    Q = _rand_q(rng, N)
    W = rng.standard_normal((N, 3)) * 0.05
    J = np.diag([2.0, 3.0, 4.0])
    n, a, ids0, p0 = m._karrs
    ids1 = ids0.copy()
    ids1[0], ids1[1], ids1[2], ids1[3] = COOK_TORRANCE_THESIS, LAMBERT, PHONG, -1
    p1 = p0.copy()
    p1[2, :3] = (0.3, 0.6, 8.0)
    noise = rng.standard_normal((N, 6))
    L = np.tril(rng.standard_normal((6, 6))) * 1e-3
    zeta = rng.standard_normal((N, 3)) * 2e-3
    zeta[:5] = 0.0                               # the series branch of exp(ζ) (|ζ| < 1e-6)
    none6 = np.zeros((0, 6))
    k = 11
    s, o = m.s_eci[k], m.o_eci[k]
    cases = 0
    for mode, dt in ((0, 5.0), (1, 5.0), (0, 0.0)):
        for nz, Lz in ((noise, L), (none6, np.zeros((6, 6)))):
            for ze in (zeta, np.zeros((0, 3))):
                for ids, p in ((ids0, p0), (ids1, p1)):
                    for sv in (s, np.full(3, np.nan)):
                        args = (dt, mode, J, np.linalg.inv(J), 3, nz, Lz, ze, sv, o, n, a, ids,
                                p, float(m.offset[k]))
                        Q1, W1, m1 = Q.copy(), W.copy(), np.full(N, -1.0)
                        _predict_rows(Q1, W1, *args, m1)
                        dq = np.empty((N if ze.shape[0] else 0, 4))
                        for dq_mode in (0, 1, 2):
                            Q2, W2, m2 = Q.copy(), W.copy(), np.full(N, -1.0)
                            BK.bpf_predict_nb(Q2, W2, *args, m2, dq, dq_mode,
                                              np.empty(BK.predict_work_size(N)))
                            assert np.array_equal(Q2, Q1) and np.array_equal(W2, W1)
                            assert np.array_equal(m2, m1)
                            cases += 1
                        if ze.shape[0]:          # dq_mode 1 kept exp(ζ_i), formed as rotvec2q
                            assert np.array_equal(dq, np.array(
                                [rotvec2q_xyz(*z) for z in ze]))
    assert cases == 3 * 2 * 2 * 2 * 2 * 3
    # a too-short scratch buffer is replaced, not overrun
    Q3, W3, m3 = Q.copy(), W.copy(), np.empty(N)
    BK.bpf_predict_nb(Q3, W3, 5.0, 0, J, J, 1, noise, L, zeta, s, o, n, a, ids0, p0,
                      float(m.offset[k]), m3, np.empty((0, 4)), 0, np.empty(10))
    Q4, W4, m4 = Q.copy(), W.copy(), np.empty(N)
    _predict_rows(Q4, W4, 5.0, 0, J, J, 1, noise, L, zeta, s, o, n, a, ids0, p0,
                  float(m.offset[k]), m4)
    assert np.array_equal(Q3, Q4) and np.array_equal(m3, m4)


def test_numpy_reference_photometry_matches_kernel(curve):
    # the plain-NumPy magnitude of the benchmark reference (bpf._predict_np) vs the numba path
    from lightcurve.filters.bpf import _predict_np

    m = MagnitudeModel(load_shape("cube_1u_mixed"), curve)
    Q = _rand_q(np.random.default_rng(12), 500)
    for k in (0, 25):
        a = _predict_np(m, Q, k)
        b = m.predict_q(Q, k)
        assert np.array_equal(np.isfinite(a), np.isfinite(b))
        fin = np.isfinite(a)
        np.testing.assert_allclose(a[fin], b[fin], atol=1e-9)


def test_tempered_ess_kernel_matches_definition():
    # N_eff = (Σw)²/Σw² of w = exp(logw + φ ll), against the estimation core's log-space ESS
    from lightcurve.estimation.particles import effective_sample_size_log

    rng = np.random.default_rng(4)
    logw = rng.standard_normal(1000) * 3
    ll = -0.5 * (rng.standard_normal(1000) * 10) ** 2
    ll[::97] = -np.inf
    for phi in (0.0, 0.01, 0.3, 1.0):
        a = logw + (phi * ll if phi else 0.0)
        ref = effective_sample_size_log(a)
        assert CP.ess_tempered(logw, ll, phi) == pytest.approx(ref, rel=1e-10)
    assert CP.ess_tempered(np.full(5, -np.inf), np.zeros(5), 1.0) == 0.0


def test_weight_kernels_match_numpy_versions():
    # numba weight bookkeeping of the BPF vs the plain-NumPy reference implementations, and
    # the normalised weights against the estimation core's normalize_log_weights
    from lightcurve.estimation.particles import normalize_log_weights
    from lightcurve.filters import bpf as B

    rng = np.random.default_rng(9)
    N = 3000
    logw = rng.standard_normal(N)
    m = 12.0 + rng.standard_normal(N) * 0.3
    m[::50] = np.inf
    ll1, ll2 = np.empty(N), np.empty(N)
    a = CP.innovation_loglik(logw, m, 12.1, 0.05, ll1)
    b = B._innov_np(logw, m, 12.1, 0.05, ll2)
    np.testing.assert_allclose(a[:2], b[:2], rtol=1e-10)
    np.testing.assert_array_equal(ll1, ll2)
    lw1, lw2, w1, w2 = logw.copy(), logw.copy(), np.empty(N), np.empty(N)
    e1, _ = CP.add_loglik_normalize(lw1, ll1, 0.3, w1)
    e2, _ = B._addnorm_np(lw2, ll2, 0.3, w2)
    ref, _ = normalize_log_weights(logw + 0.3 * ll1)
    np.testing.assert_allclose(w1, ref, rtol=1e-9, atol=1e-300)
    np.testing.assert_allclose(w2, ref, rtol=1e-9, atol=1e-300)
    assert e1 == pytest.approx(1.0 / np.sum(ref**2), rel=1e-9) and e2 == pytest.approx(e1)
    dp = rng.standard_normal((N, 3))
    W = rng.standard_normal((N, 3))
    mu1, C1 = CP.weighted_mean_cov_rows(np.hstack([dp, W]), w1)
    mu2, C2 = B._wstats_np(np.hstack([dp, W]), w1)
    np.testing.assert_allclose(mu1, mu2, atol=1e-13)
    np.testing.assert_allclose(C1, C2, atol=1e-13)


def test_filter_models_implement_the_state_space_protocols(curve):
    """The magnitude model and both dynamics are the state-space model of
    lightcurve.estimation.protocols (what the Kalman driver and the particle filter call)."""
    from lightcurve.estimation.protocols import AttitudeDynamics, MeasurementModel

    m = MagnitudeModel(load_shape("cube_1u"), curve)
    assert isinstance(m, MeasurementModel) and m.dim_y == 1
    assert isinstance(ControlledDynamics(1e-3), AttitudeDynamics)
    assert isinstance(UncontrolledDynamics(np.diag([1.0, 2.0, 3.0])), AttitudeDynamics)
    assert not isinstance(m, AttitudeDynamics) and not isinstance(object(), MeasurementModel)
    k = int(np.flatnonzero(np.isfinite(curve.mag))[0])
    x = np.concatenate([curve.truth_q[k], curve.truth_omega_rad_s[k]])
    assert m.predict(x[None], k).shape == (1, 1)
    assert m.jacobian(x, k).shape == (1, 6) and m.noise_cov(k).shape == (1, 1)
