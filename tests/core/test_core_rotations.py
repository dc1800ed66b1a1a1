"""Core rotation kernels (lightcurve.core.rotations) against independent NumPy algebra written
here and published relations (Bernard 2021 ch. 3; O'Keefe 2015 §4.1)."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from lightcurve.core import rotations as R

RNG = np.random.default_rng(3)


def _unit_q(n=None):
    q = RNG.normal(size=(4,) if n is None else (n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _A(q):
    """Bernard eq. 3.16: A(q) = (q1² − |q_v|²) I − 2 q1 [q_v×] + 2 q_v q_vᵀ (independent form)."""
    q1, v = q[0], q[1:]
    S = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return (q1 * q1 - v @ v) * np.eye(3) - 2 * q1 * S + 2 * np.outer(v, v)


def test_product_composes_attitude_matrices_eq_3_20():
    # A(q ⊗ p) = A(q) A(p) (Bernard eq. 3.20); A(q ⊙ p) = A(p) A(q) (eq. 3.21)
    for _ in range(20):
        q, p = _unit_q(), _unit_q()
        np.testing.assert_allclose(_A(R.qmul_nb(q, p)), _A(q) @ _A(p), atol=1e-14)
        np.testing.assert_allclose(R.q2dcm_nb(q), _A(q), atol=1e-15)
        out = np.empty((1, 4))
        R.qmul_batch_nb(q[None], p[None], 1.0, out)
        np.testing.assert_allclose(_A(out[0]), _A(p) @ _A(q), atol=1e-14)


def test_rotate_and_inverse_rotate_match_matrix():
    for _ in range(10):
        q, v = _unit_q(), RNG.normal(size=3)
        np.testing.assert_allclose(R.qrot_nb(q, v), _A(q) @ v, atol=1e-14)
        np.testing.assert_allclose(R.qrot_inv_nb(q, v), _A(q).T @ v, atol=1e-14)


def test_shepperd_round_trip_including_180_degrees():
    qs = list(_unit_q(20)) + [np.array([0.0, 1.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.6, 0.8])]
    for q in qs:
        back = R.dcm2q_nb(_A(q))
        assert back[0] >= 0
        np.testing.assert_allclose(_A(back), _A(q), atol=1e-14)


def test_rotation_vector_eq_3_13():
    # A = exp(−[θ×]) (Bernard eq. 3.13); and the rotation vector of q back (φ ≤ π)
    from scipy.linalg import expm

    for _ in range(10):
        th = RNG.normal(size=3)
        S = np.array([[0, -th[2], th[1]], [th[2], 0, -th[0]], [-th[1], th[0], 0]])
        q = R.rotvec2q_nb(th)
        np.testing.assert_allclose(_A(q), expm(-S), atol=1e-13)
        back = R.q2rotvec_nb(q)
        np.testing.assert_allclose(_A(R.rotvec2q_nb(back)), _A(q), atol=1e-13)
        assert np.linalg.norm(back) <= np.pi + 1e-12
    # the series branch below φ = 1e-6 is continuous with the closed form
    tiny = np.array([3e-7, -2e-7, 1e-7])
    np.testing.assert_allclose(R.rotvec2q_nb(tiny)[1:], 0.5 * tiny, rtol=1e-12)


def test_grp_eq_3_28_to_3_30_value_and_inverse():
    # 90° about z, a = 1, f = 4: p = 4 sin(45°)/(1 + cos 45°) ẑ = 4 tan(22.5°) ẑ (eq. 3.28)
    q = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])
    np.testing.assert_allclose(R.q2grp_nb(q, 1.0, 4.0), [0, 0, 4 * np.tan(np.pi / 8)], atol=1e-15)
    for a, f in ((1.0, 4.0), (0.0, 1.0), (0.5, 3.0)):
        for _ in range(10):
            q = _unit_q()
            q = q if q[0] >= 0 else -q
            np.testing.assert_allclose(R.grp2q_nb(R.q2grp_nb(q, a, f), a, f), q, atol=1e-13)


def test_grp_error_chart_is_inverted_by_from_grp_rel():
    Q, qref = _unit_q(30), _unit_q()
    P = R.grp_rel_nb(Q, qref, 1.0, 4.0)
    back = R.from_grp_rel_nb(P, qref, 1.0, 4.0)
    sign = np.sign(np.sum(back * Q, axis=1))[:, None]          # q and −q: one attitude
    np.testing.assert_allclose(sign * back, Q, atol=1e-12)
    # the chart is centred: the reference itself maps to zero
    np.testing.assert_allclose(R.grp_rel_nb(qref[None], qref, 1.0, 4.0), 0.0, atol=1e-15)


def test_mrp_dcm_shadow_and_composition_okeefe_4_1_to_4_4_and_4_21():
    for _ in range(10):
        q = _unit_q()
        s = R.q2mrp_nb(q)
        assert np.linalg.norm(s) <= 1 + 1e-12
        np.testing.assert_allclose(R.mrp2dcm_nb(s), _A(q), atol=1e-14)          # eq. 4.21
        np.testing.assert_allclose(_A(R.mrp2q_nb(s)), _A(q), atol=1e-14)
        shadow = -s / (s @ s)                                                    # eq. 4.2
        np.testing.assert_allclose(R.mrp2dcm_nb(shadow), _A(q), atol=1e-12)
        np.testing.assert_allclose(R.mrp_shadow_nb(shadow, 1.0), s, atol=1e-14)
        s2 = R.q2mrp_nb(_unit_q())
        c = R.mrp_compose_nb(s2, s)                                              # eq. 4.4
        np.testing.assert_allclose(R.mrp2dcm_nb(c), R.mrp2dcm_nb(s2) @ R.mrp2dcm_nb(s), atol=1e-12)
        assert np.linalg.norm(c) <= 1 + 1e-12


def test_mrp_kinematics_B_matrix_eq_4_3_by_finite_differences():
    # σ̇ = ¼ B(σ) ω: advance the attitude by the body rate ω for h s (q ← exp(ω h) ⊗ q) and
    # difference the MRPs (central, O(h²))
    h = 1e-6
    for _ in range(5):
        q = _unit_q()
        q = q if q[0] >= 0 else -q
        w = RNG.normal(size=3)
        sp = R.q2mrp_nb(R.qmul_nb(R.rotvec2q_nb(w * h), q))
        sm = R.q2mrp_nb(R.qmul_nb(R.rotvec2q_nb(-w * h), q))
        np.testing.assert_allclose((sp - sm) / (2 * h), 0.25 * R.mrp_B_nb(R.q2mrp_nb(q)) @ w,
                                   atol=1e-7)


def test_mrp_dcm_vector_jacobian_eq_4_32_by_finite_differences():
    h = 1e-6
    s, a = RNG.normal(size=3) * 0.4, RNG.normal(size=3)
    J = np.empty((3, 3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        J[:, j] = (R.mrp2dcm_nb(s + e) @ a - R.mrp2dcm_nb(s - e) @ a) / (2 * h)
    np.testing.assert_allclose(R.mrp_dcm_vec_jac_nb(s, a), J, atol=1e-8)


def test_euler_321_eq_3_7():
    for _ in range(10):
        phi, th, psi = RNG.uniform(-np.pi, np.pi), RNG.uniform(-1.5, 1.5), RNG.uniform(-np.pi, np.pi)
        c, s = np.cos, np.sin
        R1 = np.array([[1, 0, 0], [0, c(psi), s(psi)], [0, -s(psi), c(psi)]])
        R2 = np.array([[c(th), 0, -s(th)], [0, 1, 0], [s(th), 0, c(th)]])
        R3 = np.array([[c(phi), s(phi), 0], [-s(phi), c(phi), 0], [0, 0, 1]])
        ang = np.array([phi, th, psi])
        np.testing.assert_allclose(R.euler321_to_dcm_nb(ang), R1 @ R2 @ R3, atol=1e-14)
        q = R.euler321_to_q_nb(ang)
        np.testing.assert_allclose(_A(q), R1 @ R2 @ R3, atol=1e-14)
        np.testing.assert_allclose(R.q2euler321_nb(q), ang, atol=1e-12)


@pytest.mark.parametrize("v", [np.array([1.0, -2.0, 0.5]), np.zeros(3)])
def test_skew_is_cross_product(v):
    w = RNG.normal(size=3)
    np.testing.assert_array_equal(R.skew_nb(v) @ w, np.cross(v, w))


_CACHE_PROBE = """
import json
import numpy as np
import lightcurve.core.rotations as C
Q = np.array([[0.5, 0.5, 0.5, 0.5], [1.0, 0.0, 0.0, 0.0]])
S = np.array([[0.1, -0.2, 0.3], [0.0, 0.0, 1.0]])
o3, o4 = np.empty((2, 3)), np.empty((2, 4))
C.q2mrp_batch_nb(Q, o3)
C.mrp2q_batch_nb(S, o4)
hits = sum(f.stats.cache_hits.total() for f in (C.q2mrp_batch_nb, C.mrp2q_batch_nb))
print(json.dumps([o3.tolist(), o4.tolist(), hits]))
"""


def test_row_forms_cached_apart(tmp_path):
    # The row-wise forms are copies of one template with the same bytecode and, for these two,
    # the same numba signature ((N,k) in, (N,m) out); each must be cached in a file of its own
    # and load from it in a new process (a shared entry would hand mrp2q the code of q2mrp).
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    runs = [json.loads(subprocess.run([sys.executable, "-c", _CACHE_PROBE], env=env,
                                      capture_output=True, text=True, check=True).stdout)
            for _ in range(2)]
    Q = np.array([[0.5, 0.5, 0.5, 0.5], [1.0, 0.0, 0.0, 0.0]])
    S = np.array([[0.1, -0.2, 0.3], [0.0, 0.0, 1.0]])
    for out in runs:
        np.testing.assert_array_equal(out[0], np.stack([R.q2mrp_nb(q) for q in Q]))
        np.testing.assert_array_equal(out[1], np.stack([R.mrp2q_nb(s) for s in S]))
    assert runs[0][2] == 0 and runs[1][2] == 2
