"""The one RK4 step and the error dynamics (lightcurve.core.dynamics) against independent
references: SciPy's DOP853 on Euler's equations (Bernard 2021 eq. 4.12–4.13), conservation
laws, a plain NumPy RK4 of O'Keefe 2015 eq. B.1 (reaction wheels), the closed-form
constant-rate solution and SciPy's ``expm`` for Van Loan."""

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from lightcurve.core import dynamics as D

RNG = np.random.default_rng(11)
J = np.array([[12.0, 0.8, -0.5], [0.8, 21.0, 1.1], [-0.5, 1.1, 30.0]])
JI = np.linalg.inv(J)


def _unit_q():
    q = RNG.normal(size=4)
    return q / np.linalg.norm(q)


def _qdot(q, w):
    # Bernard eq. 4.12 component-wise
    return np.concatenate([[-0.5 * q[1:] @ w], 0.5 * (q[0] * w - np.cross(w, q[1:]))])


def _rhs_gg(k, rhat):
    def f(t, x):
        q, w = x[:4] / np.linalg.norm(x[:4]), x[4:]
        A = _A(q)
        u = A @ rhat
        T = k * np.cross(u, J @ u)                      # Bernard appendix A gravity gradient
        return np.concatenate([_qdot(x[:4], w), JI @ (T - np.cross(w, J @ w))])   # eq. 4.13
    return f


def _A(q):
    q1, v = q[0], q[1:]
    S = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return (q1 * q1 - v @ v) * np.eye(3) - 2 * q1 * S + 2 * np.outer(v, v)


def _same_attitude(q1, q2, atol):
    np.testing.assert_allclose(_A(q1), _A(q2), atol=atol)


def test_torque_free_rk4_matches_dop853_and_conserves_momentum_and_energy():
    q0, w0 = _unit_q(), RNG.normal(size=3) * 0.05
    q, w = q0.copy(), w0.copy()
    D.rk4_nb(q, w, 100.0, 1000, J, JI, None)             # 0.1 s steps
    sol = solve_ivp(_rhs_gg(0.0, np.array([1.0, 0, 0])), (0, 100.0), np.concatenate([q0, w0]),
                    method="DOP853", rtol=1e-12, atol=1e-12)
    _same_attitude(q, sol.y[:4, -1] / np.linalg.norm(sol.y[:4, -1]), 1e-9)
    np.testing.assert_allclose(w, sol.y[4:, -1], atol=1e-11)
    # conserved: inertial angular momentum Aᵀ J ω and energy ½ ωᵀ J ω
    np.testing.assert_allclose(_A(q).T @ J @ w, _A(q0).T @ J @ w0, rtol=1e-10)
    np.testing.assert_allclose(w @ J @ w, w0 @ J @ w0, rtol=1e-11)
    assert abs(np.linalg.norm(q) - 1.0) < 1e-15


def test_constant_torque_and_batch_kernel_agree_with_single_state():
    T = np.array([1e-3, -2e-3, 5e-4])
    Q = np.array([_unit_q() for _ in range(70)])
    W = RNG.normal(size=(70, 3)) * 0.03
    Qb, Wb = Q.copy(), W.copy()
    D.rk4_propagate_nb(Qb, Wb, J, JI, 0.2, 25, T)
    for i in (0, 33, 69):
        q, w = Q[i].copy(), W[i].copy()
        D.rk4_nb(q, w, 5.0, 25, J, JI, T)
        np.testing.assert_array_equal(q, Qb[i])       # one step function, bit for bit
        np.testing.assert_array_equal(w, Wb[i])
    # the torque changes the rate as dω/dt ≈ J⁻¹T at small rates: compare with DOP853
    q0, w0 = np.array([1.0, 0, 0, 0]), np.zeros(3)
    q, w = q0.copy(), w0.copy()
    D.rk4_nb(q, w, 10.0, 100, J, JI, T)
    f = lambda t, x: np.concatenate([_qdot(x[:4], x[4:]), JI @ (T - np.cross(x[4:], J @ x[4:]))])
    sol = solve_ivp(f, (0, 10.0), np.concatenate([q0, w0]), method="DOP853", rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(w, sol.y[4:, -1], atol=1e-12)


def test_gravity_gradient_term_in_every_stage_matches_dop853():
    # LEO: k = 3μ/|r|³ at 7000 km; fast tumble so that the torque varies within a step
    k = 3 * 3.986004418e14 / 7.0e6 ** 3
    rhat = np.array([0.3, -0.5, 0.81])
    rhat /= np.linalg.norm(rhat)
    q0, w0 = _unit_q(), np.array([0.02, -0.05, 0.03])

    def step(q, w, dt, n):
        import numba

        @numba.njit
        def run(q, w, dt, n, Jm, Km, gg):
            a = (q[0], q[1], q[2], q[3], w[0], w[1], w[2])
            for _ in range(n):
                a = D.rk4_step_xyz(a[0], a[1], a[2], a[3], a[4], a[5], a[6], dt, D.mat9(Jm),
                                   D.mat9(Km), None, gg, None)
            return np.array(a)
        return run(q, w, dt, n, J, JI, (k, rhat[0], rhat[1], rhat[2]))

    x = step(q0, w0, 0.5, 400)
    sol = solve_ivp(_rhs_gg(k, rhat), (0, 200.0), np.concatenate([q0, w0]), method="DOP853",
                    rtol=1e-12, atol=1e-13)
    ref = sol.y[:, -1]
    _same_attitude(x[:4], ref[:4] / np.linalg.norm(ref[:4]), 1e-8)
    np.testing.assert_allclose(x[4:], ref[4:], atol=1e-10)
    # and the torque really acts: without it the rate differs by far more than that
    q, w = q0.copy(), w0.copy()
    D.rk4_nb(q, w, 200.0, 400, J, JI, None)
    assert np.max(np.abs(w - ref[4:])) > 1e-6


def test_reaction_wheels_okeefe_b1_against_plain_rk4_of_q_omega_wheel_speeds():
    # O'Keefe 2015 §2.4: I = diag(10.5, 8, 7.5) kg m², four wheels G_s, J_s = 0.001 kg m²
    c45 = np.cos(np.radians(45.0))
    G = np.array([[0, 0, c45, -c45], [c45, c45, -c45, -c45], [c45, -c45, 0, 0]])
    Js = 0.001
    I = np.diag([10.5, 8.0, 7.5])
    Irw = I - Js * G @ G.T
    u = np.array([0.01, -0.02, 0.015, 0.005])           # N m, below the 30 mN m limit
    L = np.array([1e-5, 0.0, -2e-5])

    def f(x):   # state [q, ω, Ω]; eq. B.1 with h_s = J_s (Ω + G_sᵀ ω), u_s = ḣ_s
        q, w, Om = x[:4], x[4:7], x[7:]
        H = Irw @ w + G @ (Js * (Om + G.T @ w))
        wd = np.linalg.solve(Irw, -np.cross(w, H) - G @ u + L)
        return np.concatenate([_qdot(q, w), wd, u / Js - G.T @ wd])

    x = np.concatenate([_unit_q(), [0.02, -0.01, 0.03], [100.0, -50.0, 20.0, 0.0]])
    h, n = 0.1, 200
    ref = x.copy()
    for _ in range(n):
        k1 = f(ref)
        k2 = f(ref + 0.5 * h * k1)
        k3 = f(ref + 0.5 * h * k2)
        k4 = f(ref + h * k3)
        ref = ref + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        ref[:4] /= np.linalg.norm(ref[:4])

    import numba

    @numba.njit
    def run(q, w, hs, Jm, Km, G, u, L, h, n):
        a = (q[0], q[1], q[2], q[3], w[0], w[1], w[2])
        T = (L[0] , L[1], L[2])
        tau = G @ u
        for _ in range(n):
            hw = G @ hs
            a = D.rk4_step_xyz(a[0], a[1], a[2], a[3], a[4], a[5], a[6], h, D.mat9(Jm), D.mat9(Km),
                               T, None, (hw[0], hw[1], hw[2], tau[0], tau[1], tau[2]))
            hs = hs + h * u
        return np.array(a), hs

    w0 = x[4:7]
    a, hs = run(x[:4].copy(), w0.copy(), Js * (x[7:] + G.T @ w0), Irw, np.linalg.inv(Irw), G, u, L, h, n)
    _same_attitude(a[:4], ref[:4], 1e-11)
    np.testing.assert_allclose(a[4:], ref[4:7], atol=1e-12)
    np.testing.assert_allclose(hs / Js - G.T @ a[4:], ref[7:], rtol=1e-11, atol=1e-9)


def test_constant_rate_step_is_exact():
    q, w = _unit_q(), RNG.normal(size=3) * 0.1
    dt = 7.3
    th = w * dt
    phi = np.linalg.norm(th)
    dq = np.concatenate([[np.cos(phi / 2)], np.sin(phi / 2) * th / phi])
    expect = np.concatenate([[dq[0] * q[0] - dq[1:] @ q[1:]],
                             dq[0] * q[1:] + q[0] * dq[1:] - np.cross(dq[1:], q[1:])])
    np.testing.assert_allclose(D.const_rate_nb(q, w, dt), expect, atol=1e-15)
    Q = np.array([q, q])
    D.const_rate_batch_nb(Q, np.array([w, w]), dt)
    np.testing.assert_array_equal(Q[0], D.const_rate_nb(q, w, dt))


def test_van_loan_matches_scipy_expm():
    F = RNG.normal(size=(6, 6)) * 0.3
    Qc = np.diag([0, 0, 0, 1e-6, 2e-6, 3e-6])
    Phi, Qd = np.empty((6, 6)), np.empty((6, 6))
    D.van_loan_nb(F, Qc, 2.5, Phi, Qd)
    M = np.zeros((12, 12))
    M[:6, :6], M[:6, 6:], M[6:, 6:] = -F, Qc, F.T
    E = expm(M * 2.5)
    np.testing.assert_allclose(Phi, E[6:, 6:].T, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(Qd, Phi @ E[:6, 6:], rtol=1e-10, atol=1e-18)


def test_error_dynamics_eq_7_37_by_finite_differences_of_euler_equations():
    # F_ωω = ∂ω̇/∂ω = J⁻¹([(Jω)×] − [ω×] J) for torque-free motion
    w = RNG.normal(size=3) * 0.1
    F = np.empty((6, 6))
    D.error_F_nb(w, J, JI, True, F)
    h = 1e-7
    num = np.empty((3, 3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        fp = JI @ (-np.cross(w + e, J @ (w + e)))
        fm = JI @ (-np.cross(w - e, J @ (w - e)))
        num[:, j] = (fp - fm) / (2 * h)
    np.testing.assert_allclose(F[3:, 3:], num, atol=1e-9)
    np.testing.assert_allclose(F[:3, 3:], np.eye(3))
    # controlled model (eq. 7.24): Φ in closed form equals exp(F Δt)
    D.error_F_nb(w, J, JI, False, F)
    np.testing.assert_allclose(D.controlled_transition_nb(w, 3.0), expm(F * 3.0), atol=1e-13)
