"""Quaternion kinematics (Bernard 2021 eq. 4.12) and the exact constant-rate step."""

import numpy as np
import pytest

from lightcurve import rotations as rot
from lightcurve.core.dynamics import const_rate_nb as const_rate_step_nb
from lightcurve.dynamics import (
    propagate_constant_rate,
    quat_derivative,
    rk4_propagate,
)

RNG = np.random.default_rng(20211)


def _rand_q(n=None):
    q = RNG.normal(size=(4,) if n is None else (n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def test_quat_derivative_matches_omega_product_and_scalar_first_eq_4_12():
    # Bernard eq. 4.12 written out component-wise, independently of quat_mult:
    # q̇1 = −½ q_v·ω ; q̇_v = ½ (q1 ω − ω × q_v)
    q = _rand_q(5)
    w = RNG.normal(size=(5, 3)) * 0.1
    expect = np.empty((5, 4))
    expect[:, 0] = -0.5 * np.sum(q[:, 1:] * w, axis=1)
    expect[:, 1:] = 0.5 * (q[:, :1] * w - np.cross(w, q[:, 1:]))
    np.testing.assert_allclose(quat_derivative(q, w), expect, rtol=0, atol=1e-15)
    # and equal to ½ [0, ω] ⊗ q with the rotations module's product
    wq = np.concatenate([np.zeros((5, 1)), w], axis=1)
    np.testing.assert_allclose(quat_derivative(q, w), 0.5 * rot.quat_mult(wq, q), atol=1e-15)
    for i in range(5):
        np.testing.assert_allclose(quat_derivative(q[i], w[i]), expect[i], atol=1e-15)


def test_quat_derivative_is_time_derivative_of_exact_solution():
    # central difference in time of the exact constant-rate solution (truncation O(h²))
    q = _rand_q()
    w = np.array([0.3, -0.1, 0.2])
    h = 1e-5
    fd = (propagate_constant_rate(q, w, h) - propagate_constant_rate(q, w, -h)) / (2 * h)
    np.testing.assert_allclose(fd, quat_derivative(q, w), atol=1e-10)


def test_body_rate_sense_vector_transformation():
    # Passive inertial→body: a fixed inertial vector appears to rotate at −ω in body axes,
    # d(v_b)/dt = −ω × v_b = v_b × ω  (passive attitude matrix kinematics Ȧ = −[ω×]A, Markley & Crassidis ch. 3).
    q = _rand_q()
    w = np.array([0.02, 0.05, -0.03])
    vI = np.array([0.3, -0.4, 0.8])
    h = 1e-4
    vb_p = rot.quat_rotate(propagate_constant_rate(q, w, h), vI)
    vb_m = rot.quat_rotate(propagate_constant_rate(q, w, -h), vI)
    vb = rot.quat_rotate(q, vI)
    np.testing.assert_allclose((vb_p - vb_m) / (2 * h), -np.cross(w, vb), atol=1e-9)


def test_constant_rate_step_properties():
    q = _rand_q(4)
    w = RNG.normal(size=(4, 3)) * 0.2
    # group property: two steps = one step of the summed time
    two = propagate_constant_rate(propagate_constant_rate(q, w, 1.7), w, 2.4)
    np.testing.assert_allclose(two, propagate_constant_rate(q, w, 4.1), atol=1e-14)
    # inertial rate direction A(q)ᵀ ω is constant for rotation about a fixed axis
    q7 = propagate_constant_rate(q, w, 7.0)
    np.testing.assert_allclose(rot.quat_rotate_inv(q7, w), rot.quat_rotate_inv(q, w), atol=1e-14)
    # rotation angle of q(t) ⊗ q(0)⁻¹ is |ω| t (mod 2π)
    ang = rot.attitude_error_angle(q7, q)
    expect = np.mod(np.linalg.norm(w, axis=1) * 7.0 + np.pi, 2 * np.pi) - np.pi
    np.testing.assert_allclose(ang, np.abs(expect), atol=1e-12)
    # numba kernel agrees
    for i in range(4):
        np.testing.assert_allclose(const_rate_step_nb(q[i], w[i], 7.0), q7[i], atol=1e-14)


def test_exact_step_equals_rk4_integration_of_kinematics():
    # Acceptance: with an isotropic inertia Euler's equations give ω̇ = 0, so the RK4 kernel
    # integrates the kinematics alone; it must reproduce the exact step (RK4 error O(Δt⁴)).
    q = _rand_q(20)
    w = RNG.normal(size=(20, 3)) * 0.1
    J = 3.0 * np.eye(3)
    qr, wr = rk4_propagate(q, w, J, 0.01, 1000)  # 10 s
    qe = propagate_constant_rate(q, w, 10.0)
    np.testing.assert_allclose(wr, w, atol=1e-16)
    assert np.max(rot.attitude_error_angle(qr, qe)) < 1e-11
    np.testing.assert_allclose(qr, qe, atol=1e-11)  # same sign (no flip in the kernel)


@pytest.mark.parametrize("bad_q, msg", [
    (np.array([1.0, 0.1, 0.0, 0.0]), "unit"),
    (np.array([np.nan, 0, 0, 1.0]), "NaN"),
    (np.array([1.0, 0, 0]), "shape"),
])
def test_bad_quaternion_rejected(bad_q, msg):
    with pytest.raises(ValueError, match=msg):
        quat_derivative(bad_q, [0, 0, 0.1])
    with pytest.raises(ValueError, match=msg):
        propagate_constant_rate(bad_q, [0, 0, 0.1], 1.0)


def test_bad_rate_and_step_rejected():
    q = np.array([1.0, 0, 0, 0])
    with pytest.raises(ValueError, match="omega.*shape"):
        quat_derivative(q, [0.1, 0.2])
    with pytest.raises(ValueError, match="omega.*NaN"):
        propagate_constant_rate(q, [0.1, np.nan, 0], 1.0)
    with pytest.raises(ValueError, match="dt"):
        propagate_constant_rate(q, [0.1, 0, 0], np.inf)
