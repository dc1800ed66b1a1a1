"""Linearised error dynamics F (Bernard 2021 eq. 7.24, 7.37, appendix A) against central
finite differences of the nonlinear model, to 1e-6 relative."""

import numpy as np
import pytest

from lightcurve import rotations as rot
from lightcurve.dynamics import (
    DragTorque,
    GravityGradientTorque,
    SRPTorque,
    TorqueSum,
    acs_noise_covariance,
    controlled_F,
    drag_torque,
    drag_torque_jacobian,
    eta_noise_covariance,
    gravity_gradient_jacobian,
    gravity_gradient_torque,
    integrate_truth,
    nonlinear_error_rate,
    srp_torque,
    srp_torque_jacobian,
    state_derivative,
    transition_matrix,
    uncontrolled_F,
    uncontrolled_F_models,
)

Q = rot.euler321_to_quat(np.radians([-42.4122, 59.1601, 48.9897]))
W = np.array([0.021, -0.034, 0.047])
J = np.array([[12.0, 0.8, -0.5], [0.8, 21.0, 1.1], [-0.5, 1.1, 30.0]])
R = np.array([4.5e6, -3.1e6, 4.0e6])          # ~6.8e6 m, LEO
V = np.cross([0.1, 0.3, 0.95], R)
V = V / np.linalg.norm(V) * 7.6e3
SUN = np.array([0.3, 0.8, -0.52])
SUN /= np.linalg.norm(SUN)
# a box-with-panel facet model (body axes); centres of pressure offset from the CM
FACETS = dict(
    areas_m2=np.array([1.0, 1.0, 1.5, 1.5, 0.8, 0.8, 6.0]),
    normals_body=np.array([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
                           [0.0, 0.6, 0.8]]),
    centers_body_m=np.array([[0.6, 0.05, 0.1], [-0.5, 0.05, 0.1], [0.0, 0.7, 0.1], [0.0, -0.6, 0.1],
                             [0.05, 0.0, 0.9], [0.05, 0.0, -0.8], [0.3, 2.5, -0.2]]),
)
C_SPEC = np.array([0.1, 0.2, 0.3, 0.1, 0.5, 0.0, 0.05])
C_DIFF = np.array([0.5, 0.3, 0.2, 0.6, 0.1, 0.3, 0.15])
REL = 1e-6


def _fd_torque_dtheta(fun, q, h=1e-5):
    """Central FD of T(exp(δθ) ⊗ q) with respect to δθ (3×3)."""
    out = np.zeros((3, 3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        tp = fun(rot.quat_mult(rot.rotvec_to_quat(e), q))
        tm = fun(rot.quat_mult(rot.rotvec_to_quat(-e), q))
        out[:, j] = (tp - tm) / (2 * h)
    return out


def _assert_rel(an, fd, rel=REL):
    scale = np.max(np.abs(fd))
    assert scale > 0
    err = np.max(np.abs(an - fd))
    assert err <= rel * scale, f"max abs err {err:.3g} vs scale {scale:.3g} (rel {err / scale:.3g})"


def test_gravity_gradient_jacobian_fd():
    an = gravity_gradient_jacobian(R, Q, J)
    fd = _fd_torque_dtheta(lambda q: gravity_gradient_torque(R, q, J), Q)
    _assert_rel(an, fd)


def test_srp_jacobian_fd():
    kw = dict(c_spec=C_SPEC, c_diff=C_DIFF, lit_fraction=0.7, sun_distance_m=1.01 * 1.495978707e11, **FACETS)
    assert 0 < np.sum(FACETS["normals_body"] @ rot.quat_rotate(Q, SUN) > 0) < 7  # some lit, some not
    an = srp_torque_jacobian(Q, SUN, **kw)
    fd = _fd_torque_dtheta(lambda q: srp_torque(q, SUN, **kw), Q)
    _assert_rel(an, fd)


def test_drag_jacobian_fd():
    kw = dict(Cd=2.3, **FACETS)
    vb = rot.quat_rotate(Q, V - np.cross([0, 0, 7.292115e-5], R))
    assert 0 < np.sum(FACETS["normals_body"] @ vb > 0) < 7
    an = drag_torque_jacobian(Q, R, V, **kw)
    fd = _fd_torque_dtheta(lambda q: drag_torque(q, R, V, **kw), Q)
    _assert_rel(an, fd)


def _fd_F(q_hat, w_hat, Jm, torque_fn, h=1e-6):
    F = np.zeros((6, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        F[:, j] = (nonlinear_error_rate(e, q_hat, w_hat, Jm, torque_fn)
                   - nonlinear_error_rate(-e, q_hat, w_hat, Jm, torque_fn)) / (2 * h)
    return F


def _assert_blocks(an, fd, rel=REL):
    for rows in (slice(0, 3), slice(3, 6)):
        for cols in (slice(0, 3), slice(3, 6)):
            a, f = an[rows, cols], fd[rows, cols]
            scale = np.max(np.abs(f))
            if scale == 0:
                assert np.max(np.abs(a)) < 1e-15  # structurally zero block (expm round-off allowed)
            else:
                _assert_rel(a, f, rel)


def test_controlled_F_eq_7_24_fd():
    an = controlled_F(W)
    fd = _fd_F(Q, W, None, None)
    _assert_blocks(an, fd)
    # structure of eq. 7.24
    np.testing.assert_array_equal(an[:3, 3:], np.eye(3))
    np.testing.assert_array_equal(an[3:], 0.0)


def test_uncontrolled_F_torque_free_fd():
    an = uncontrolled_F(W, J)
    fd = _fd_F(Q, W, J, None)
    _assert_blocks(an, fd)


def test_uncontrolled_F_with_all_torques_eq_7_37_fd():
    models = TorqueSum([
        GravityGradientTorque(J, R),
        SRPTorque(c_spec=C_SPEC, c_diff=C_DIFF, sun_dir=SUN, lit_fraction=1.0, **FACETS),
        DragTorque(position=R, velocity=V, Cd=2.2, **FACETS),
    ])
    an = uncontrolled_F_models(0.0, Q, W, J, models.models)
    fd = _fd_F(Q, W, J, lambda t, q, w: models.torque(t, q, w), h=1e-6)
    _assert_blocks(an, fd)
    # the torque block is non-trivial and differs from the torque-free F
    assert np.max(np.abs(an[3:, :3])) > 1e-8
    # the environment is physically small: the torque block is tiny compared with I
    assert np.max(np.abs(an[3:, :3])) < 1e-3


def test_transition_matrix_against_propagated_perturbations():
    # Propagation check: Φ(t) from the variational equations Φ̇ = F(x̂(t)) Φ (F re-evaluated
    # along the nominal DOP853 trajectory) vs central differences of perturbed nonlinear
    # trajectories (attitude error charted as a rotation vector).
    gg = GravityGradientTorque(J, R)
    tq = lambda t, q, w: gg.torque(t, q, w)  # noqa: E731
    rhs = lambda t, x: state_derivative(t, x, J, tq)  # noqa: E731
    T = 20.0
    xh = integrate_truth(np.r_[Q, W], [0.0, T], rhs, rtol=1e-13, atol=1e-14)

    def var_rhs(t, y):
        x = y[:7]
        q = x[:4] / np.linalg.norm(x[:4])
        F = uncontrolled_F(x[4:], J, dT_dtheta=gg.dtheta(t, q))
        Phi = y[7:].reshape(6, 6)
        return np.concatenate([rhs(t, x), (F @ Phi).ravel()])

    y = integrate_truth(np.r_[Q, W, np.eye(6).ravel()], [0.0, T], var_rhs, rtol=1e-13, atol=1e-14,
                        normalize=False)[-1]
    Phi = y[7:].reshape(6, 6)
    h = 1e-5
    Phi_fd = np.zeros((6, 6))
    for j in range(6):
        cols = []
        for sgn in (1, -1):
            e = np.zeros(6)
            e[j] = sgn * h
            x0 = np.r_[rot.quat_mult(rot.rotvec_to_quat(e[:3]), Q), W + e[3:]]
            x = integrate_truth(x0, [0.0, T], rhs, rtol=1e-13, atol=1e-14)[-1]
            dth = rot.quat_to_rotvec(rot.quat_mult(x[:4], rot.quat_conj(xh[-1, :4])))
            cols.append(np.r_[dth, x[4:] - xh[-1, 4:]])
        Phi_fd[:, j] = (cols[0] - cols[1]) / (2 * h)
    _assert_blocks(Phi, Phi_fd, rel=1e-6)


def test_controlled_transition_matrix_exact_for_constant_rate():
    # For the controlled model F is constant, so Φ = exp(F Δt) must match central differences
    # of the exact constant-rate propagation of perturbed states (kinematics eq. 4.12).
    from lightcurve.dynamics import propagate_constant_rate

    dt = 15.0
    Phi = transition_matrix(controlled_F(W), dt)
    qh = propagate_constant_rate(Q, W, dt)
    h = 1e-6
    Phi_fd = np.zeros((6, 6))
    for j in range(6):
        cols = []
        for sgn in (1, -1):
            e = np.zeros(6)
            e[j] = sgn * h
            q = propagate_constant_rate(rot.quat_mult(rot.rotvec_to_quat(e[:3]), Q), W + e[3:], dt)
            cols.append(np.r_[rot.quat_to_rotvec(rot.quat_mult(q, rot.quat_conj(qh))), e[3:]])
        Phi_fd[:, j] = (cols[0] - cols[1]) / (2 * h)
    _assert_blocks(Phi, Phi_fd, rel=1e-6)


def test_noise_covariances():
    Q6 = acs_noise_covariance(2e-3)
    np.testing.assert_allclose(Q6[:3, :3], 4e-6 * np.eye(3))
    assert np.all(Q6[3:] == 0)
    dt, s = 3.0, 1e-4
    Qp = eta_noise_covariance(dt, s, "piecewise_constant")
    # η held constant: δω = η dt, δθ = η dt²/2  ⇒  Cov = s² [[dt⁴/4, dt³/2],[dt³/2, dt²]]
    np.testing.assert_allclose(Qp[0, 0], s**2 * dt**4 / 4)
    np.testing.assert_allclose(Qp[0, 3], s**2 * dt**3 / 2)
    np.testing.assert_allclose(Qp[3, 3], s**2 * dt**2)
    Qc = eta_noise_covariance(dt, s, "continuous")
    # continuous white noise: Q = ∫ Φ G G^T Φ^T for the double integrator (Bar-Shalom eq. 6.2.3-8)
    from scipy.integrate import quad

    Phi = lambda tau: np.array([[1.0, tau], [0.0, 1.0]])  # noqa: E731
    G = np.array([0.0, 1.0])
    for a in range(2):
        for b in range(2):
            val = quad(lambda tau: (Phi(dt - tau) @ G)[a] * (Phi(dt - tau) @ G)[b], 0, dt)[0]
            np.testing.assert_allclose(Qc[3 * a, 3 * b], s**2 * val, rtol=1e-10)
    assert np.all(np.linalg.eigvalsh(Qc) > 0)
    with pytest.raises(ValueError, match="kind"):
        eta_noise_covariance(dt, s, "bogus")


def test_jacobian_bad_inputs():
    with pytest.raises(ValueError, match="single quaternion"):
        gravity_gradient_jacobian(R, np.stack([Q, Q]), J)
    with pytest.raises(ValueError, match="unit"):
        gravity_gradient_jacobian(R, [1.0, 0.3, 0, 0], J)
    with pytest.raises(ValueError, match="positive definite"):
        uncontrolled_F(W, np.diag([1.0, 2.0, 0.0]))
    with pytest.raises(ValueError, match="omega"):
        controlled_F([0.1, np.nan, 0.0])
