"""Euler's equations (Bernard 2021 eq. 4.13), conservation laws, integrators."""

import numpy as np
import pytest

from lightcurve import rotations as rot
from lightcurve.dynamics import (
    angular_momentum_inertial,
    check_inertia,
    euler_omega_dot,
    integrate_truth,
    rk4_propagate,
    rotational_energy,
    state_derivative,
)

# Asymmetric body (kg m²), not diagonal in body axes, rates of a fast tumble (rad/s).
J_ASYM = np.array([[12.0, 0.8, -0.5], [0.8, 21.0, 1.1], [-0.5, 1.1, 30.0]])
W0 = np.array([0.05, -0.11, 0.07])
Q0 = rot.euler321_to_quat(np.radians([-42.4122, 59.1601, 48.9897]))  # Bernard LEO fast-spin case
T_ORBIT = 5800.0  # one LEO orbit, s


def test_euler_omega_dot_matches_component_form():
    # Principal-axis form (Euler's equations in principal axes, any dynamics text):
    # J1 ω̇1 = (J2 − J3) ω2 ω3 + T1, and cyclic.
    J = np.array([10.0, 20.0, 35.0])
    w = np.array([0.3, -0.2, 0.1])
    T = np.array([1e-3, -2e-3, 5e-4])
    expect = np.array([
        ((J[1] - J[2]) * w[1] * w[2] + T[0]) / J[0],
        ((J[2] - J[0]) * w[2] * w[0] + T[1]) / J[1],
        ((J[0] - J[1]) * w[0] * w[1] + T[2]) / J[2],
    ])
    np.testing.assert_allclose(euler_omega_dot(w, np.diag(J), T), expect, rtol=1e-14)
    np.testing.assert_allclose(euler_omega_dot(w, J, T, J_inv=np.diag(1 / J)), expect, rtol=1e-14)


def test_state_derivative_layout():
    x = np.concatenate([Q0, W0])
    T = np.array([1e-4, 0, -2e-4])
    xd = state_derivative(0.0, x, J_ASYM, lambda t, q, w: T)
    np.testing.assert_allclose(xd[:4], 0.5 * rot.quat_mult(np.r_[0.0, W0], Q0), atol=1e-16)
    np.testing.assert_allclose(xd[4:], np.linalg.solve(J_ASYM, T - np.cross(W0, J_ASYM @ W0)), rtol=1e-13)


def test_axisymmetric_torque_free_matches_analytic_solution():
    # Axisymmetric body J = diag(It, It, I3): ω3 constant, the transverse rate rotates at
    # λ = (I3 − It)/It ω3 (torque-free axisymmetric body, e.g. Wie, Space Vehicle Dynamics and Control §6.4): ω1 + iω2 = (ω1+iω2)(0) e^{iλt}.
    It, I3 = 10.0, 16.0
    J = np.diag([It, It, I3])
    w0 = np.array([0.04, -0.02, 0.3])
    lam = (I3 - It) / It * w0[2]
    t = np.linspace(0, 200.0, 11)
    x = integrate_truth(np.r_[Q0, w0], t, lambda tt, xx: state_derivative(tt, xx, J))
    z = (w0[0] + 1j * w0[1]) * np.exp(1j * lam * t)
    np.testing.assert_allclose(x[:, 4], z.real, atol=1e-12)
    np.testing.assert_allclose(x[:, 5], z.imag, atol=1e-12)
    np.testing.assert_allclose(x[:, 6], w0[2], atol=1e-13)
    qr, wr = rk4_propagate(Q0, w0, J, 0.05, 4000)
    np.testing.assert_allclose(wr, [z[-1].real, z[-1].imag, w0[2]], atol=1e-9)
    assert rot.attitude_error_angle(qr, x[-1, :4]) < 1e-8


def test_torque_free_one_orbit_conserves_momentum_and_energy():
    # Acceptance: DOP853 with rtol = atol = 1e-12 over one LEO orbit conserves the
    # inertial angular momentum A(q)ᵀ J ω and the energy ½ ωᵀ J ω to 1e-9 relative.
    t = np.linspace(0.0, T_ORBIT, 59)
    x = integrate_truth(np.r_[Q0, W0], t, lambda tt, xx: state_derivative(tt, xx, J_ASYM))
    H = angular_momentum_inertial(x[:, :4], x[:, 4:], J_ASYM)
    E = rotational_energy(x[:, 4:], J_ASYM)
    dH = np.max(np.linalg.norm(H - H[0], axis=1)) / np.linalg.norm(H[0])
    dE = np.max(np.abs(E - E[0])) / E[0]
    print(f"DOP853 one orbit: max |ΔH|/|H| = {dH:.2e}, max |ΔE|/E = {dE:.2e}")
    assert dH < 1e-9 and dE < 1e-9
    # the rate really moves (asymmetric tumble), so conservation is not trivial
    assert np.max(np.abs(x[:, 4:] - W0)) > 1e-2

    # RK4 kernel drift over the same orbit (reported; step 0.1 s)
    qr, wr = rk4_propagate(Q0, W0, J_ASYM, 0.1, int(T_ORBIT / 0.1))
    Hr = angular_momentum_inertial(qr, wr, J_ASYM)
    dHr = np.linalg.norm(Hr - H[0]) / np.linalg.norm(H[0])
    dEr = abs(rotational_energy(wr, J_ASYM) - E[0]) / E[0]
    err = rot.attitude_error_angle(qr, x[-1, :4])
    print(f"RK4 dt=0.1 s one orbit: |ΔH|/|H| = {dHr:.2e}, |ΔE|/E = {dEr:.2e}, attitude diff {err:.2e} rad")
    assert dHr < 1e-8 and dEr < 1e-8 and err < 1e-6


def test_rk4_parallel_matches_serial_and_sequential_calls():
    from lightcurve.core.dynamics import rk4_nb
    from lightcurve.dynamics import rk4_propagate_nb

    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w = rng.normal(size=(50, 3)) * 0.1
    Ji = np.linalg.inv(J_ASYM)
    T = np.array([1e-4, -2e-4, 3e-5])
    q1, w1 = q.copy(), w.copy()
    rk4_propagate_nb(q1, w1, J_ASYM, Ji, 0.2, 50, T)
    q2, w2 = q.copy(), w.copy()
    for i in range(q2.shape[0]):   # the same step, one state at a time
        rk4_nb(q2[i], w2[i], 0.2 * 50, 50, J_ASYM, Ji, T)
    np.testing.assert_array_equal(q1, q2)
    np.testing.assert_array_equal(w1, w2)
    # constant torque agrees with DOP853 truth
    x = integrate_truth(np.r_[q[0], w[0]], [0.0, 10.0],
                        lambda tt, xx: state_derivative(tt, xx, J_ASYM, lambda *_: T))
    np.testing.assert_allclose(w1[0], x[-1, 4:], atol=1e-10)
    assert rot.attitude_error_angle(q1[0], x[-1, :4]) < 1e-8  # RK4 O(Δt⁴) at Δt = 0.2 s
    np.testing.assert_allclose(np.linalg.norm(q1, axis=1), 1.0, atol=1e-15)


@pytest.mark.parametrize("J, msg", [
    (np.diag([1.0, -1.0, 2.0]), "positive definite"),
    (np.array([[1.0, 0.5, 0], [0, 1, 0], [0, 0, 1]]), "symmetric"),
    (np.diag([1.0, np.nan, 2.0]), "NaN"),
    (np.eye(2), "shape"),
    (np.zeros((3, 3)), "symmetric and nonzero"),
])
def test_bad_inertia_rejected(J, msg):
    with pytest.raises(ValueError, match=msg):
        check_inertia(J)
    with pytest.raises(ValueError):
        rk4_propagate(Q0, W0, J, 0.1, 1)


def test_bad_state_rejected():
    with pytest.raises(ValueError, match="shape"):
        state_derivative(0.0, np.zeros(6), J_ASYM)
    with pytest.raises(ValueError, match="unit"):
        rk4_propagate([1.0, 0.2, 0, 0], W0, J_ASYM, 0.1, 1)
    with pytest.raises(ValueError, match="omega"):
        rk4_propagate(Q0, [0.1, np.nan, 0], J_ASYM, 0.1, 1)
    with pytest.raises(ValueError, match="incompatible shapes"):
        rk4_propagate(np.stack([Q0, Q0, Q0]), np.stack([W0, W0]), J_ASYM, 0.1, 1)
    with pytest.raises(ValueError, match="nsteps"):
        rk4_propagate(Q0, W0, J_ASYM, 0.1, -1)
    with pytest.raises(ValueError, match="t_eval"):
        integrate_truth(np.r_[Q0, W0], [2.0, 1.0], lambda t, x: x)
