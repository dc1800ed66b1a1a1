"""Rotation algebra: property tests (hypothesis), thesis reference values and scipy interop.

Sources: Bernard 2021 eq. 3.7, 3.13, 3.16–3.30, 9.4–9.6; O'Keefe 2015 eq. 4.1–4.4, 4.21, 4.32;
Schaub & Junkins, *Analytical Mechanics of Space Systems* (MRP addition, eq. 3.152).
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from lightcurve import rotations as R

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


@st.composite
def unit_quats(draw):
    v = draw(arrays(float, 4, elements=finite))
    n = np.linalg.norm(v)
    if n < 1e-3:
        v = np.array([1.0, 0, 0, 0]); n = 1.0
    return v / n


@st.composite
def rotvecs(draw, max_angle=np.pi - 1e-3):
    v = draw(arrays(float, 3, elements=finite))
    n = np.linalg.norm(v)
    ang = draw(st.floats(0.0, max_angle))
    if n < 1e-6:
        return np.zeros(3)
    return v / n * ang


def assert_same_quat(a, b, atol=1e-10):
    """q and −q are the same attitude: compare up to sign."""
    a, b = np.asarray(a), np.asarray(b)
    assert min(np.max(np.abs(a - b)), np.max(np.abs(a + b))) < atol, (a, b)


def independent_euler321(phi, theta, psi):
    """Bernard eq. 3.7 written independently: A = R1(psi) R2(theta) R3(phi), passive."""
    c, s = np.cos, np.sin
    R1 = np.array([[1, 0, 0], [0, c(psi), s(psi)], [0, -s(psi), c(psi)]])
    R2 = np.array([[c(theta), 0, -s(theta)], [0, 1, 0], [s(theta), 0, c(theta)]])
    R3 = np.array([[c(phi), s(phi), 0], [-s(phi), c(phi), 0], [0, 0, 1]])
    return R1 @ R2 @ R3


@settings(max_examples=200, deadline=None)
@given(unit_quats(), unit_quats())
def test_composition_matches_matrix_product(q, p):
    # Bernard eq. 3.20–3.21: A(q⊗p) = A(q)A(p), A(q⊙p) = A(p)A(q)
    np.testing.assert_allclose(R.quat_to_dcm(R.quat_mult(q, p)), R.quat_to_dcm(q) @ R.quat_to_dcm(p), atol=1e-12)
    np.testing.assert_allclose(R.quat_to_dcm(R.quat_odot(q, p)), R.quat_to_dcm(p) @ R.quat_to_dcm(q), atol=1e-12)
    assert abs(np.linalg.norm(R.quat_mult(q, p)) - 1) < 1e-12  # norm preservation


@settings(max_examples=200, deadline=None)
@given(unit_quats())
def test_round_trips(q):
    qn = R.quat_normalize(q)
    A = R.quat_to_dcm(q)
    np.testing.assert_allclose(A @ A.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(A) == pytest.approx(1.0, abs=1e-12)
    assert_same_quat(R.dcm_to_quat(A), qn)
    e, phi = R.quat_to_axis_angle(q)
    np.testing.assert_allclose(R.quat_to_dcm(R.axis_angle_to_quat(e, phi)), A, atol=1e-10)
    th = R.quat_to_rotvec(q)
    np.testing.assert_allclose(R.rotvec_to_dcm(th), A, atol=1e-10)
    assert_same_quat(R.rotvec_to_quat(th), qn)
    for a, f in ((1.0, None), (0.0, 1.0), (1.0, 1.0), (0.5, 3.0)):
        if a + qn[0] < 1e-3:  # Gibbs vector is singular at 180° (q1 = 0)
            continue
        assert_same_quat(R.grp_to_quat(R.quat_to_grp(qn, a, f), a, f), qn)
    s = R.quat_to_mrp(q)
    assert np.linalg.norm(s) <= 1 + 1e-12
    np.testing.assert_allclose(R.mrp_to_dcm(s), A, atol=1e-10)
    assert_same_quat(R.mrp_to_quat(s), qn)
    ang = R.quat_to_euler321(q)
    np.testing.assert_allclose(R.euler321_to_dcm(ang), A, atol=1e-8)
    np.testing.assert_allclose(R.quat_to_dcm(R.euler321_to_quat(ang)), A, atol=1e-8)


@settings(max_examples=100, deadline=None)
@given(unit_quats())
def test_mrp_shadow_same_attitude(q):
    s = R.quat_to_mrp(q)
    if np.linalg.norm(s) < 1e-3:
        return
    ss = R.mrp_shadow(s)
    np.testing.assert_allclose(R.mrp_to_dcm(ss), R.mrp_to_dcm(s), atol=1e-9)
    sw = R.mrp_switch(ss)
    assert np.linalg.norm(sw) <= 1 + 1e-12
    np.testing.assert_allclose(R.mrp_to_dcm(sw), R.mrp_to_dcm(s), atol=1e-9)
    if np.linalg.norm(s) < 1 - 1e-9:  # away from |σ| = 1 the switched set is unique
        np.testing.assert_allclose(sw, s, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(unit_quats(), unit_quats())
def test_mrp_composition(q, p):
    # Schaub & Junkins eq. 3.152 / O'Keefe eq. 4.3: C(σ_FN) = C(σ_FB) C(σ_BN)
    s_fb, s_bn = R.quat_to_mrp(q), R.quat_to_mrp(p)
    s_fn = R.mrp_compose(s_fb, s_bn)
    np.testing.assert_allclose(R.mrp_to_dcm(s_fn), R.mrp_to_dcm(s_fb) @ R.mrp_to_dcm(s_bn), atol=1e-8)
    np.testing.assert_allclose(R.mrp_add(s_bn, s_fb), s_fn, atol=1e-12)


def test_mrp_dcm_jacobian_finite_difference():
    rng = np.random.default_rng(3)
    for _ in range(20):
        s = rng.normal(size=3) * 0.4
        a = rng.normal(size=3)
        J = R.mrp_dcm_vec_jacobian(s, a)
        h = 1e-6
        Jfd = np.column_stack([(R.mrp_to_dcm(s + h * e) @ a - R.mrp_to_dcm(s - h * e) @ a) / (2 * h)
                               for e in np.eye(3)])
        np.testing.assert_allclose(J, Jfd, rtol=1e-6, atol=1e-8)


def test_thesis_leo_fast_spin_initial_attitude():
    # Bernard §9.3 LEO fast-spin initial 3-2-1 angles (deg): φ = −42.4122, θ = 59.1601, ψ = 48.9897
    ang = np.radians([-42.4122, 59.1601, 48.9897])
    A_ref = independent_euler321(*ang)
    np.testing.assert_allclose(R.euler321_to_dcm(ang), A_ref, atol=1e-15)
    q = R.euler321_to_quat(ang)
    np.testing.assert_allclose(R.quat_to_dcm(q), A_ref, atol=1e-14)
    np.testing.assert_allclose(np.degrees(R.quat_to_euler321(q)), [-42.4122, 59.1601, 48.9897], atol=1e-10)
    # independent: the axis of A is its eigenvector for eigenvalue 1, angle from the trace
    w, V = np.linalg.eig(A_ref)
    e = np.real(V[:, np.argmin(np.abs(w - 1))])
    phi = np.arccos((np.trace(A_ref) - 1) / 2)
    e_q, phi_q = R.quat_to_axis_angle(q)
    assert phi_q == pytest.approx(phi, abs=1e-12)
    assert abs(abs(e_q @ e) - 1) < 1e-10


def test_elementary_rotation_and_vector_transform():
    # passive rotation of the frame by +90° about z: inertial x-axis has body components (0, -1, 0)
    q = R.axis_angle_to_quat([0, 0, 1.0], np.pi / 2)
    np.testing.assert_allclose(R.quat_rotate(q, [1.0, 0, 0]), [0, -1, 0], atol=1e-15)
    np.testing.assert_allclose(R.quat_rotate_inv(q, [0, -1.0, 0]), [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(R.rotvec_to_dcm([0, 0, np.pi / 2]), R.quat_to_dcm(q), atol=1e-15)


def test_axis_angle_special_cases():
    e, phi = R.quat_to_axis_angle([1.0, 0, 0, 0])
    assert phi == 0.0 and np.allclose(e, [1, 0, 0])
    q180 = R.axis_angle_to_quat([0, 1.0, 0], np.pi)
    e, phi = R.quat_to_axis_angle(q180)
    assert phi == pytest.approx(np.pi)
    assert abs(e @ [0, 1, 0]) == pytest.approx(1.0)
    A = np.diag([-1.0, 1.0, -1.0])  # 180° about y, Shepperd branch
    np.testing.assert_allclose(R.quat_to_dcm(R.dcm_to_quat(A)), A, atol=1e-15)


def test_grp_small_angle_and_special_cases():
    th = np.array([1e-3, -2e-3, 5e-4])
    q = R.rotvec_to_quat(th)
    # default a=1, f=4: |p| ≈ φ to second order (Bernard eq. 3.28 remark)
    np.testing.assert_allclose(R.quat_to_grp(q), th, rtol=1e-6)
    # Gibbs vector a=0, f=1: tan(φ/2) ê
    np.testing.assert_allclose(R.quat_to_grp(q, 0.0, 1.0), np.tan(np.linalg.norm(th) / 2) * th / np.linalg.norm(th), rtol=1e-12)
    # MRP a=f=1 equals quat_to_mrp
    np.testing.assert_allclose(R.quat_to_grp(q, 1.0, 1.0), R.quat_to_mrp(q), rtol=1e-12)


def test_attitude_error():
    q_est = R.euler321_to_quat(np.radians([10.0, 20.0, 30.0]))
    dth = np.radians([1.0, -2.0, 0.5])
    q_true = R.quat_mult(R.rotvec_to_quat(dth), q_est)
    np.testing.assert_allclose(R.attitude_error_rotvec(q_true, q_est), dth, atol=1e-12)
    assert R.attitude_error_angle(q_true, q_est) == pytest.approx(np.linalg.norm(dth), abs=1e-12)
    assert R.attitude_error_angle(q_true, -q_est) == pytest.approx(np.linalg.norm(dth), abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(unit_quats(), arrays(float, 3, elements=finite))
def test_scipy_interop(q, v):
    rot = R.to_scipy(q)
    np.testing.assert_allclose(rot.as_matrix(), R.quat_to_dcm(q), atol=1e-12)
    np.testing.assert_allclose(rot.apply(v), R.quat_rotate(q, v), atol=1e-12)
    assert_same_quat(R.from_scipy(rot), q, atol=1e-12)
    # scipy's own 3-2-1 ("ZYX", intrinsic) Euler angles describe the active rotation A(q)ᵀ
    ang = R.quat_to_euler321(q)
    np.testing.assert_allclose(rot.inv().as_matrix(), R.euler321_to_dcm(ang).T, atol=1e-8)


def test_vectorised_matches_single():
    rng = np.random.default_rng(0)
    q = R.quat_normalize(rng.normal(size=(50, 4)))
    p = R.quat_normalize(rng.normal(size=(50, 4)))
    v = rng.normal(size=(50, 3))
    batch = R.quat_mult(q, p)
    for i in range(50):
        np.testing.assert_allclose(batch[i], R.quat_mult(q[i], p[i]), atol=1e-15)
        np.testing.assert_allclose(R.qmul_nb(q[i], p[i]), batch[i], atol=1e-15)
        np.testing.assert_allclose(R.qrot_nb(q[i], v[i]), R.quat_rotate(q[i], v[i]), atol=1e-14)
        np.testing.assert_allclose(R.qrot_inv_nb(q[i], v[i]), R.quat_rotate_inv(q[i], v[i]), atol=1e-14)
        np.testing.assert_allclose(R.q2dcm_nb(q[i]), R.quat_to_dcm(q[i]), atol=1e-15)
        np.testing.assert_allclose(R.grp2q_nb(R.q2grp_nb(q[i], 1.0, 4.0), 1.0, 4.0), q[i], atol=1e-12)
        np.testing.assert_allclose(R.rotvec2q_nb(v[i]), R.rotvec_to_quat(v[i]), atol=1e-14)
    np.testing.assert_allclose(R.quat_to_dcm(q) @ v[..., None], R.quat_rotate(q, v)[..., None], atol=1e-13)


@pytest.mark.parametrize("bad, msg", [
    ([1.0, 0, 0], "shape"),
    ([np.nan, 0, 0, 1], "NaN"),
    ([1.0, 1.0, 0, 0], "unit"),
])
def test_bad_input(bad, msg):
    with pytest.raises(ValueError, match=msg):
        R.quat_to_dcm(bad)
