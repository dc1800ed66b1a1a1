"""Attitude parameterisations: quaternion, DCM, Euler axis/angle, rotation vector, Euler 3-2-1,
generalised Rodrigues parameters (GRP) and modified Rodrigues parameters (MRP).

Conventions (DESIGN.md; Bernard 2021 ch. 3, O'Keefe 2015 ch. 4)
-------------------------------------------------------------------
* Quaternion ``q = [q1, q2, q3, q4]`` with the **scalar first** (``q[..., 0]``), unit norm.
* Attitude is **inertial→body, passive**: ``v_b = A(q) v_I`` with (Bernard eq. 3.16–3.17)
  ``A(q) = (q1² − |q_v|²) I + 2 q_v q_vᵀ − 2 q1 [q_v×]``.
* Composition ``q ⊗ p`` (Bernard eq. 3.20) satisfies ``A(q ⊗ p) = A(q) A(p)``, so
  ``q_x→z = q_y→z ⊗ q_x→y``; ``q ⊙ p`` (eq. 3.21) satisfies ``A(q ⊙ p) = A(p) A(q)``.
* Rotation vector ``θ = φ ê`` maps to ``A = exp(−[θ×])`` (eq. 3.13) and
  ``q = [cos(φ/2), ê sin(φ/2)]`` (eq. 3.8–3.11).
* Euler 3-2-1 angles ``(φ, θ, ψ)`` about z, y, x: ``A = R1(ψ) R2(θ) R3(φ)`` (eq. 3.7), with the
  passive elementary rotations ``R3(φ) = [[c, s, 0], [−s, c, 0], [0, 0, 1]]`` etc.
* GRP (eq. 3.28–3.30): ``p = f q_v / (a + q1)``; default ``a = 1, f = 2(a + 1) = 4``; Gibbs is
  ``a = 0, f = 1``, MRP is ``a = f = 1``.
* MRP (O'Keefe eq. 4.1–4.4, Schaub & Junkins): ``σ = q_v/(1 + q1)``, shadow set
  ``σˢ = −σ/|σ|²``; DCM (O'Keefe eq. 4.21) ``C = I + (8[σ×]² − 4(1−|σ|²)[σ×])/(1+|σ|²)²``,
  identical to ``A(q)``.
* Attitude error (Bernard eq. 9.4–9.6): ``δq = q_true ⊗ q_est⁻¹``; the error angle is the
  rotation angle of ``δq`` and the error rotation vector its rotation vector (body axes).
* ``scipy.spatial.transform.Rotation`` stores quaternions scalar last and is *active*:
  :func:`to_scipy` returns the rotation ``R`` with ``R.as_matrix() == A(q)``, i.e.
  ``R.apply(v_I) == v_b``; ``R.inv()`` is the body→inertial (active attitude) rotation.

Every numpy-layer function accepts a single value (``(4,)`` or ``(3,)``) or stacked arrays
(``(..., 4)``, ``(..., 3)``) and raises ``ValueError`` naming the argument on wrong shapes, NaN or,
where a unit quaternion is required, a norm further than ``1e-6`` from one (no silent
renormalisation). The arithmetic is done once, by the numba kernels of
:mod:`lightcurve.core.rotations` (re-exported here: ``qmul_nb``, ``qrot_nb``, … on single 1-D
float64 arrays, for hot loops; they do not validate); this module validates, broadcasts and
reshapes.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .core import rotations as C
from .core.rotations import (grp2q_nb, q2dcm_nb, q2grp_nb, qmul_nb, qnormalize_nb, qrot_inv_nb,
                             qrot_nb, qrot_xyz_nb, rotvec2q_nb)

__all__ = [
    "UNIT_TOL",
    "skew",
    "check_unit_quat",
    "quat_mult",
    "quat_odot",
    "quat_conj",
    "quat_inv",
    "quat_normalize",
    "quat_average",
    "quat_identity",
    "quat_to_dcm",
    "dcm_to_quat",
    "quat_rotate",
    "quat_rotate_inv",
    "axis_angle_to_quat",
    "quat_to_axis_angle",
    "rotvec_to_quat",
    "quat_to_rotvec",
    "rotvec_to_dcm",
    "euler321_to_quat",
    "quat_to_euler321",
    "euler321_to_dcm",
    "quat_to_grp",
    "grp_to_quat",
    "quat_to_mrp",
    "mrp_to_quat",
    "mrp_shadow",
    "mrp_switch",
    "mrp_add",
    "mrp_compose",
    "mrp_to_dcm",
    "mrp_dcm_vec_jacobian",
    "attitude_error",
    "attitude_error_angle",
    "attitude_error_rotvec",
    "to_scipy",
    "from_scipy",
    "qmul_nb",
    "qrot_nb",
    "qrot_inv_nb",
    "qrot_xyz_nb",
    "q2dcm_nb",
    "q2grp_nb",
    "grp2q_nb",
    "qnormalize_nb",
    "rotvec2q_nb",
]

UNIT_TOL = 1e-6
"""Largest accepted deviation of a quaternion's norm from one."""


# ----------------------------------------------------------------------------------------
# validation helpers
# ----------------------------------------------------------------------------------------
def _as_array(x, last: int, name: str) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected an array of numbers, got {type(x).__name__}") from None
    if a.ndim == 0 or a.shape[-1] != last:
        raise ValueError(f"{name}: expected shape (..., {last}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return a


def _as_quat(q, name: str = "q", unit: bool = True) -> np.ndarray:
    a = _as_array(q, 4, name)
    if unit:
        n = np.linalg.norm(a, axis=-1)
        bad = np.abs(n - 1.0) > UNIT_TOL
        if np.any(bad):
            worst = float(np.max(np.abs(n - 1.0)))
            raise ValueError(
                f"{name}: not a unit quaternion (| |q| - 1 | = {worst:.3g} > {UNIT_TOL:g}); "
                "normalise it explicitly with quat_normalize if that is intended"
            )
    return a


def _as_vec3(v, name: str = "v") -> np.ndarray:
    return _as_array(v, 3, name)


def _rowwise(kernel, out_tail, *arrays, args=()):
    """Broadcast ``arrays`` over their leading axes, call ``kernel(*rows, *args, out)`` on
    contiguous (N, …) rows and return ``out`` reshaped to ``lead + out_tail``."""
    tails = [a.shape[a.ndim - t:] for a, t in arrays]
    lead = np.broadcast_shapes(*(a.shape[:a.ndim - t] for a, t in arrays))
    rows = [np.ascontiguousarray(np.broadcast_to(a, lead + tail), dtype=np.float64)
            .reshape((-1,) + tail) for (a, _), tail in zip(arrays, tails)]
    n = rows[0].shape[0]
    out = np.empty((n,) + tuple(out_tail))
    kernel(*rows, *args, out)
    return out.reshape(lead + tuple(out_tail))


def check_unit_quat(q, name: str = "q") -> np.ndarray:
    """Validate a unit quaternion (or stack) and return it as a float array.

    Raises ``ValueError`` for a wrong shape, NaN/inf, or a norm off by more than ``UNIT_TOL``.
    """
    return _as_quat(q, name, unit=True)


def skew(v) -> np.ndarray:
    """Cross-product matrix ``[v×]`` such that ``[v×] w = v × w``; shape (..., 3, 3)."""
    v = _as_vec3(v, "v")
    return _rowwise(C.skew_batch_nb, (3, 3), (v, 1))


# ----------------------------------------------------------------------------------------
# quaternion algebra
# ----------------------------------------------------------------------------------------
def quat_identity(shape=()) -> np.ndarray:
    """Identity quaternion(s) ``[1, 0, 0, 0]`` of batch shape ``shape``."""
    q = np.zeros(tuple(np.atleast_1d(shape)) + (4,) if shape != () else (4,))
    q[..., 0] = 1.0
    return q


def quat_mult(q, p) -> np.ndarray:
    """Quaternion product ``q ⊗ p`` (Bernard eq. 3.20): ``A(q ⊗ p) = A(q) A(p)``.

    ``q ⊗ p = [q1 p1 − q_v·p_v, q1 p_v + p1 q_v − q_v × p_v]``. Inputs need not be unit.
    """
    q = _as_quat(q, "q", False)
    p = _as_quat(p, "p", False)
    return _rowwise(C.qmul_batch_nb, (4,), (q, 1), (p, 1), args=(-1.0,))


def quat_odot(q, p) -> np.ndarray:
    """Quaternion product ``q ⊙ p`` (Bernard eq. 3.21): ``A(q ⊙ p) = A(p) A(q)``; equals ``p ⊗ q``."""
    q = _as_quat(q, "q", False)
    p = _as_quat(p, "p", False)
    return _rowwise(C.qmul_batch_nb, (4,), (q, 1), (p, 1), args=(1.0,))


def quat_conj(q) -> np.ndarray:
    """Conjugate ``[q1, −q_v]``; the inverse of a unit quaternion."""
    q = _as_quat(q, "q", False)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_inv(q) -> np.ndarray:
    """Inverse ``q* / |q|²`` (any nonzero quaternion)."""
    q = _as_quat(q, "q", False)
    n2 = np.sum(q * q, axis=-1, keepdims=True)
    if np.any(n2 == 0):
        raise ValueError("q: the zero quaternion has no inverse")
    return quat_conj(q) / n2


def quat_normalize(q, positive_scalar: bool = True) -> np.ndarray:
    """Scale to unit norm; with ``positive_scalar`` flip the sign so that ``q1 >= 0``.

    ``q`` and ``−q`` are the same attitude; the sign convention makes comparisons and
    round trips well defined. Raises ``ValueError`` for a (near-)zero quaternion.
    """
    q = _as_quat(q, "q", False)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < 1e-12):
        raise ValueError("q: cannot normalise a zero quaternion")
    out = q / n
    if positive_scalar:
        out = np.where(out[..., :1] < 0, -out, out)
    return out


def quat_to_dcm(q) -> np.ndarray:
    """Attitude matrix ``A(q)`` (inertial→body; Bernard eq. 3.16–3.17), shape (..., 3, 3)."""
    q = _as_quat(q)
    return _rowwise(C.q2dcm_batch_nb, (3, 3), (q, 1))


def dcm_to_quat(A, orthonormal_tol: float = 1e-6) -> np.ndarray:
    """Unit quaternion (``q1 >= 0``) of an attitude matrix, by Shepperd's method.

    Robust for every rotation angle including 180°. Raises ``ValueError`` when ``A`` is not a
    proper orthonormal matrix within ``orthonormal_tol``.
    """
    try:
        A = np.asarray(A, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("A: expected an array of numbers") from None
    if A.ndim < 2 or A.shape[-2:] != (3, 3):
        raise ValueError(f"A: expected shape (..., 3, 3), got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError("A: contains NaN or infinite values")
    err = np.abs(np.einsum("...ji,...jk->...ik", A, A) - np.eye(3)).max(axis=(-2, -1))
    det = np.linalg.det(A)
    if np.any(err > orthonormal_tol) or np.any(det < 0):
        raise ValueError("A: not a proper orthonormal rotation matrix "
                         f"(max |AᵀA − I| = {float(np.max(err)):.3g}, det min {float(np.min(det)):.3g})")
    return _rowwise(C.dcm2q_batch_nb, (4,), (A, 2))


def quat_rotate(q, v) -> np.ndarray:
    """Transform a vector from inertial to body axes: ``v_b = A(q) v_I`` (Bernard eq. 3.26).

    ``q`` (..., 4) and ``v`` (..., 3) broadcast against each other.
    """
    q = _as_quat(q)
    v = _as_vec3(v, "v")
    return _rowwise(C.qrot_batch_nb, (3,), (q, 1), (v, 1), args=(False,))


def quat_rotate_inv(q, v) -> np.ndarray:
    """Transform a vector from body to inertial axes: ``v_I = A(q)ᵀ v_b``."""
    q = _as_quat(q)
    v = _as_vec3(v, "v")
    return _rowwise(C.qrot_batch_nb, (3,), (q, 1), (v, 1), args=(True,))


# ----------------------------------------------------------------------------------------
# axis/angle and rotation vector
# ----------------------------------------------------------------------------------------
def axis_angle_to_quat(axis, angle_rad) -> np.ndarray:
    """Quaternion of a rotation by ``angle_rad`` about unit ``axis`` (Bernard eq. 3.8–3.11).

    The axis must be a unit vector (checked to 1e-6). The result has ``q1 = cos(φ/2)``
    (negative for φ > π).
    """
    e = _as_vec3(axis, "axis")
    n = np.linalg.norm(e, axis=-1)
    if np.any(np.abs(n - 1.0) > UNIT_TOL):
        raise ValueError("axis: not a unit vector")
    phi = np.asarray(angle_rad, dtype=float)
    if not np.all(np.isfinite(phi)):
        raise ValueError("angle_rad: contains NaN or infinite values")
    h = 0.5 * phi[..., None]
    return np.concatenate([np.cos(h), np.sin(h) * e], axis=-1)


def quat_to_axis_angle(q):
    """Euler axis ``ê`` (...,3) and angle ``φ ∈ [0, π]`` (rad) of a unit quaternion.

    ``q`` and ``−q`` give the same result. At φ = 0 the axis is undefined and ``[1, 0, 0]`` is
    returned; at φ = π the axis sign is that of the largest component of ``q_v`` made positive.
    """
    q = quat_normalize(_as_quat(q))
    n = np.linalg.norm(q[..., 1:], axis=-1)
    phi = 2.0 * np.arctan2(n, q[..., 0])
    safe = n > 1e-15
    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.where(safe[..., None], q[..., 1:] / np.where(safe, n, 1.0)[..., None], 0.0)
    e = np.where(safe[..., None], e, np.array([1.0, 0.0, 0.0]))
    return e, phi


def rotvec_to_quat(theta) -> np.ndarray:
    """Quaternion of rotation vector ``θ = φ ê`` (rad): ``[cos(φ/2), ê sin(φ/2)]``; any |θ|."""
    th = _as_vec3(theta, "theta")
    return _rowwise(C.rotvec2q_batch_nb, (4,), (th, 1))


def quat_to_rotvec(q) -> np.ndarray:
    """Rotation vector ``θ = φ ê`` with ``φ ∈ [0, π]`` of a unit quaternion (sign-independent)."""
    q = quat_normalize(_as_quat(q))
    return _rowwise(C.q2rotvec_batch_nb, (3,), (q, 1))


def rotvec_to_dcm(theta) -> np.ndarray:
    """``A = exp(−[θ×]) = cos φ I + (1−cos φ) ê êᵀ − sin φ [ê×]`` (Bernard eq. 3.13), computed
    as ``A(q(θ))`` (eq. 3.8–3.11, 3.17)."""
    return quat_to_dcm(rotvec_to_quat(theta))


# ----------------------------------------------------------------------------------------
# Euler 3-2-1
# ----------------------------------------------------------------------------------------
def euler321_to_dcm(angles_rad) -> np.ndarray:
    """``A = R1(ψ) R2(θ) R3(φ)`` for angles ``(φ, θ, ψ)`` about z, y, x in rad (Bernard eq. 3.7)."""
    a = _as_vec3(angles_rad, "angles_rad")
    return _rowwise(C.euler321_to_dcm_batch_nb, (3, 3), (a, 1))


def euler321_to_quat(angles_rad) -> np.ndarray:
    """Quaternion of 3-2-1 angles ``(φ, θ, ψ)`` (rad): ``q_x(ψ) ⊗ q_y(θ) ⊗ q_z(φ)``, ``q1 >= 0``."""
    a = _as_vec3(angles_rad, "angles_rad")
    return _rowwise(C.euler321_to_q_batch_nb, (4,), (a, 1))


def quat_to_euler321(q) -> np.ndarray:
    """3-2-1 angles ``(φ, θ, ψ)`` in rad, φ, ψ ∈ (−π, π], θ ∈ [−π/2, π/2].

    At gimbal lock (|θ| = π/2) φ and ψ are not unique; ψ = 0 is returned there.
    """
    q = _as_quat(q)
    return _rowwise(C.q2euler321_batch_nb, (3,), (q, 1))


# ----------------------------------------------------------------------------------------
# GRP and MRP
# ----------------------------------------------------------------------------------------
def _grp_af(a, f):
    a = float(a)
    f = 2.0 * (a + 1.0) if f is None else float(f)
    if not (0.0 <= a <= 1.0) or f <= 0:
        raise ValueError(f"GRP parameters: need 0 <= a <= 1 and f > 0, got a={a}, f={f}")
    return a, f


def quat_to_grp(q, a: float = 1.0, f: float | None = None) -> np.ndarray:
    """Generalised Rodrigues parameters ``p = f q_v/(a + q1)`` (Bernard eq. 3.28).

    Default ``a = 1, f = 2(a+1) = 4`` (then ``|p| ≈ φ`` for small angles). Singular at
    ``q1 = −a``; the sign of ``q`` is kept as given (flip it beforehand to pick the short way).
    """
    a, f = _grp_af(a, f)
    q = _as_quat(q)
    if np.any(np.abs(a + q[..., 0]) < 1e-12):
        raise ValueError("q: GRP singular at q1 = -a (rotation of 360 degrees for a = 1)")
    return _rowwise(C.q2grp_batch_nb, (3,), (q, 1), args=(a, f))


def grp_to_quat(p, a: float = 1.0, f: float | None = None) -> np.ndarray:
    """Quaternion from GRP (Bernard eq. 3.29–3.30).

    ``q1 = (−a|p|² + f √(f² + (1−a²)|p|²)) / (f² + |p|²)``, ``q_v = (a + q1) p / f``.
    """
    a, f = _grp_af(a, f)
    p = _as_vec3(p, "p")
    return _rowwise(C.grp2q_batch_nb, (4,), (p, 1), args=(a, f))


def quat_to_mrp(q) -> np.ndarray:
    """MRP ``σ = q_v/(1 + q1)`` of a unit quaternion, taking the sign with ``q1 >= 0``, so |σ| ≤ 1
    (O'Keefe eq. 4.1)."""
    q = quat_normalize(_as_quat(q))
    return _rowwise(C.q2mrp_batch_nb, (3,), (q, 1))


def mrp_to_quat(s) -> np.ndarray:
    """Unit quaternion of an MRP: ``q1 = (1−|σ|²)/(1+|σ|²)``, ``q_v = 2σ/(1+|σ|²)``."""
    s = _as_vec3(s, "sigma")
    return _rowwise(C.mrp2q_batch_nb, (4,), (s, 1))


def mrp_shadow(s) -> np.ndarray:
    """Shadow MRP set ``σˢ = −σ/|σ|²`` (same attitude; O'Keefe eq. 4.2). Undefined at σ = 0."""
    s = _as_vec3(s, "sigma")
    if np.any(np.sum(s * s, axis=-1) == 0):
        raise ValueError("sigma: the shadow set of the zero MRP is at infinity")
    return _rowwise(C.mrp_shadow_batch_nb, (3,), (s, 1), args=(0.0,))


def mrp_switch(s, threshold: float = 1.0) -> np.ndarray:
    """Replace σ by its shadow set where ``|σ| > threshold`` (default 1), keeping |σ| ≤ 1."""
    s = _as_vec3(s, "sigma")
    return _rowwise(C.mrp_shadow_batch_nb, (3,), (s, 1), args=(float(threshold),))


def mrp_compose(s_outer, s_inner) -> np.ndarray:
    """MRP of ``C(σ_outer) C(σ_inner)`` (O'Keefe eq. 4.3–4.4; Schaub & Junkins eq. 3.152).

    For ``[FN] = [FB][BN]`` call ``mrp_compose(σ_FB, σ_BN)``. Where the formula's denominator
    vanishes (a 360° composite), the inner set is replaced by its shadow. The result is
    switched to |σ| ≤ 1.
    """
    s2 = _as_vec3(s_outer, "s_outer")
    s1 = _as_vec3(s_inner, "s_inner")
    return _rowwise(C.mrp_compose_batch_nb, (3,), (s2, 1), (s1, 1))


def mrp_add(s1, s2) -> np.ndarray:
    """MRP of the rotation ``σ1`` followed by ``σ2``: ``C(result) = C(σ2) C(σ1)``.

    (The Basilisk ``addMRP`` ordering; ``mrp_add(σ_BN, σ_FB) = σ_FN``.)
    """
    return mrp_compose(s2, s1)


def mrp_to_dcm(s) -> np.ndarray:
    """``C(σ) = I + (8[σ×]² − 4(1 − |σ|²)[σ×]) / (1 + |σ|²)²`` (O'Keefe eq. 4.21); equals A(q)."""
    s = _as_vec3(s, "sigma")
    return _rowwise(C.mrp2dcm_batch_nb, (3, 3), (s, 1))


def mrp_dcm_vec_jacobian(s, a) -> np.ndarray:
    """Jacobian ``∂(C(σ) a)/∂σ`` (3×3), the derivative of ``[BN] a`` used by O'Keefe eq. 4.32
    (:func:`lightcurve.core.rotations.mrp_dcm_vec_jac_nb`)."""
    s = _as_vec3(s, "sigma")
    a = _as_vec3(a, "a")
    return _rowwise(C.mrp_dcm_vec_jac_batch_nb, (3, 3), (s, 1), (a, 1))


# ----------------------------------------------------------------------------------------
# attitude error
# ----------------------------------------------------------------------------------------
def attitude_error(q_true, q_est) -> np.ndarray:
    """Error quaternion ``δq = q_true ⊗ q_est⁻¹`` (Bernard eq. 9.4), sign chosen with δq1 >= 0."""
    q_true = _as_quat(q_true, "q_true")
    q_est = _as_quat(q_est, "q_est")
    return quat_normalize(quat_mult(q_true, q_est * np.array([1.0, -1, -1, -1])))


def attitude_error_angle(q_true, q_est) -> np.ndarray:
    """Total attitude error angle (rad, in [0, π]) between two attitudes (Bernard eq. 9.5)."""
    dq = attitude_error(q_true, q_est)
    return 2.0 * np.arctan2(np.linalg.norm(dq[..., 1:], axis=-1), np.abs(dq[..., 0]))


def attitude_error_rotvec(q_true, q_est) -> np.ndarray:
    """Error rotation vector (rad, body axes) of ``δq`` (Bernard eq. 9.6; exact, not small-angle)."""
    return quat_to_rotvec(attitude_error(q_true, q_est))


def quat_average(q, weights=None) -> np.ndarray:
    """Weighted average attitude of quaternions q (n,4) → (4,), ``q1 >= 0``.

    The maximiser of ``Σ wᵢ (qᵀqᵢ)²`` over unit q: the eigenvector of ``M = Σ wᵢ qᵢ qᵢᵀ`` with the
    largest eigenvalue (Markley, Cheng, Crassidis & Oshman 2007, "Averaging quaternions",
    JGCD 30(4), eq. 12–13). Independent of the signs of the qᵢ (q and −q are one attitude).
    """
    q = _as_quat(q).reshape(-1, 4)
    w = np.ones(q.shape[0]) if weights is None else np.asarray(weights, float).reshape(-1)
    if w.shape[0] != q.shape[0] or not np.all(w >= 0) or not w.sum() > 0:
        raise ValueError("weights must be non-negative, one per quaternion, not all zero")
    M = (q * w[:, None]).T @ q
    _, vec = np.linalg.eigh(M)
    return quat_normalize(vec[:, -1])


# ----------------------------------------------------------------------------------------
# scipy interoperability
# ----------------------------------------------------------------------------------------
def to_scipy(q):
    """``scipy.spatial.transform.Rotation`` ``R`` with ``R.as_matrix() == A(q)``.

    So ``R.apply(v_I)`` gives body components; ``R.inv()`` is the active body→inertial rotation
    (the orientation of the body axes in inertial space). scipy stores quaternions scalar last.
    """
    q = _as_quat(q)
    # scipy's matrix for scalar-last [x, y, z, w] is A(q)ᵀ, so A(q) belongs to the conjugate.
    return Rotation.from_quat(np.concatenate([-q[..., 1:], q[..., :1]], axis=-1))


def from_scipy(rot) -> np.ndarray:
    """Inverse of :func:`to_scipy`: the quaternion (``q1 >= 0``) with ``A(q) == rot.as_matrix()``."""
    x = np.asarray(rot.as_quat(), dtype=float)
    return quat_normalize(np.concatenate([x[..., 3:], -x[..., :3]], axis=-1))
