"""Exact rotation symmetries of a faceted shape, and attitudes modulo them.

A proper rotation G (3×3, body axes) is a symmetry of the shape when it maps every facet onto a
facet with the same area, the same reflection parameters (and, for an anisotropic BRDF, the
same tangent up to sign), the same normal and the same centre, and leaves the inertia tensor
unchanged (G J Gᵀ = J). Then the attitudes A (inertial→body) and G·A give the same magnitude at
every epoch (the facet normals in inertial axes, Aᵀ G ᵀ n, run over the same set), and
ω ↦ G ω maps one solution of Euler's equations onto another (the same J), so no lightcurve can
tell them apart: the posterior of a lost-in-space search has one copy of every mode per
symmetry. The identity is always one; a 10-sided prism with equal caps has the 20 rotations of
D₁₀, a one-material cube the 24 of the octahedral group, the Bernard (2021) Table 9.2 cube
(+X facet of a different material) the identity only.

Validity: shapes with at least two non-parallel facet normals (a shape whose normals are all
parallel — a single plate — has a continuous symmetry about that normal, which a finite list
cannot hold; only the identity is returned for it, documented here and in its test).
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot

__all__ = ["shape_symmetries", "symmetry_quaternions", "error_modulo_symmetry",
           "fold_to_reference"]

_ANISOTROPIC = {"ashikhmin_shirley"}


def _frame(u, v):
    e1 = u / np.linalg.norm(u)
    e3 = np.cross(u, v)
    e3 /= np.linalg.norm(e3)
    return np.column_stack([e1, np.cross(e3, e1), e3])


def shape_symmetries(shape, tol: float = 1e-6) -> np.ndarray:
    """Proper rotations (K, 3, 3), body axes, that map ``shape`` onto itself (module docstring),
    identity first.

    Candidates map two non-parallel facet normals (facets 0 and i₁) onto every pair of facets
    alike in area, reflection parameters and mutual angle (O(F²) candidates); each candidate is
    then checked on every facet (normal and centre to 1e-5, area and parameters to ``tol``) and
    on the inertia tensor (relative 1e-6).
    """
    n = np.asarray(shape.normals_body, float)
    c = np.asarray(shape.centers_body_m, float)
    F = len(n)
    key = np.column_stack([np.asarray(shape.areas_m2, float), np.asarray(shape.params, float)])
    names = np.asarray(shape.brdf_names, dtype=object)
    tang = np.asarray(shape.tangents_body, float)
    J = np.asarray(shape.inertia_kg_m2, float)
    jscale = max(float(np.abs(J).max()), 1e-300)
    same = np.array([[np.allclose(key[i], key[j], atol=tol) and names[i] == names[j]
                      for j in range(F)] for i in range(F)])
    aniso = np.array([str(nm) in _ANISOTROPIC for nm in names])
    eye = np.eye(3)
    i1 = next((k for k in range(1, F) if np.linalg.norm(np.cross(n[0], n[k])) > 1e-3), None)
    if i1 is None:
        return eye[None].copy()
    F0 = _frame(n[0], n[i1])
    cos01 = float(n[0] @ n[i1])
    cscale = max(float(np.abs(c).max()), 1e-12)
    out = [eye]
    for a in range(F):
        if not same[a, 0]:
            continue
        for b in range(F):
            if b == a or not same[b, i1] or abs(n[a] @ n[b] - cos01) > 1e-6:
                continue
            G = _frame(n[a], n[b]) @ F0.T
            if any(np.allclose(G, H, atol=1e-6) for H in out):
                continue
            if not np.allclose(G @ J @ G.T, J, atol=1e-6 * jscale):
                continue
            nn, cc, tt = n @ G.T, c @ G.T, tang @ G.T
            ok = True
            for k in range(F):
                m = np.flatnonzero(same[k] & np.all(np.abs(n - nn[k]) < 1e-5, axis=1)
                                   & np.all(np.abs(c - cc[k]) < 1e-5 * cscale, axis=1))
                if aniso[k]:
                    m = [j for j in m if abs(abs(float(tang[j] @ tt[k])) - 1.0) < 1e-6]
                if len(m) == 0:
                    ok = False
                    break
            if ok:
                out.append(G)
    return np.array(out)


def symmetry_quaternions(shape) -> np.ndarray:
    """The symmetries of :func:`shape_symmetries` as quaternions (K, 4), scalar first, identity
    first: the attitude q (inertial→body) and g ⊗ q give the same lightcurve."""
    return np.array([rot.dcm_to_quat(G) for G in shape_symmetries(shape)])


def error_modulo_symmetry(q_true, q_est, sym) -> float:
    """Smallest attitude error angle (deg) between ``q_true`` and any symmetric equivalent
    G·A(q_est) of the estimate; ``sym``: rotations (K, 3, 3) from :func:`shape_symmetries`."""
    A = rot.quat_to_dcm(np.asarray(q_est, float))
    qs = np.array([rot.dcm_to_quat(G @ A) for G in np.asarray(sym, float)])
    return float(np.degrees(np.min(rot.attitude_error_angle(
        np.broadcast_to(np.asarray(q_true, float), qs.shape), qs))))


def fold_to_reference(Q, W, q_ref, gq):
    """Map every attitude Q (N, 4) and body rate W (N, 3) to its symmetric equivalent
    (g ⊗ q, R_g ω) nearest to ``q_ref`` (largest |⟨g ⊗ q, q_ref⟩|), over the symmetry
    quaternions ``gq`` (K, 4) → (Q', W', index of g per row). With the identity alone this
    returns the input."""
    Q = np.asarray(Q, float)
    W = np.asarray(W, float)
    gq = np.asarray(gq, float)
    if gq.shape[0] <= 1:
        return Q.copy(), W.copy(), np.zeros(Q.shape[0], np.int64)
    # ⟨g ⊗ q, r⟩ for every g: (K, N)
    imgs = np.stack([rot.quat_mult(np.broadcast_to(g, Q.shape), Q) for g in gq])
    score = np.abs(imgs @ np.asarray(q_ref, float))
    k = np.argmax(score, axis=0)
    Qf = imgs[k, np.arange(Q.shape[0])]
    Qf /= np.linalg.norm(Qf, axis=1, keepdims=True)
    R = rot.quat_to_dcm(gq)
    Wf = np.einsum("nij,nj->ni", R[k], W)
    return Qf, Wf, k.astype(np.int64)
