"""Exact rotation symmetries of a shape (lightcurve.acquisition.symmetry).

Group orders are those of the shapes' geometry: the 10-sided rocket body (shapes/rocket_body:
a regular decagonal prism, equal caps) has the dihedral group D₁₀ of order 2·10 = 20; a cube
with one material on all faces the octahedral group of order 24; the Bernard (2021) Table 9.2
cube (shapes/cube_1u: the +X facet of a different material from the others) only the identity.
"""

from __future__ import annotations

import numpy as np
import pytest

from lightcurve import rotations as rot
from lightcurve.acquisition.symmetry import (error_modulo_symmetry, fold_to_reference,
                                             shape_symmetries, symmetry_quaternions)
from lightcurve.photometry import load_shape


def _is_group(G):
    """Closed under products and inverses, proper rotations, identity first."""
    assert np.allclose(G[0], np.eye(3))
    for R in G:
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0.999
        for S in G:
            assert any(np.allclose(R @ S, T, atol=1e-6) for T in G)


@pytest.mark.parametrize("name,order", [("rocket_body", 20), ("cube_1u", 1)])
def test_library_shapes_have_their_geometric_symmetry_groups(name, order):
    G = shape_symmetries(load_shape(name))
    assert len(G) == order
    _is_group(G)


def test_one_material_cube_has_the_24_rotations_of_the_octahedral_group(sym_cube_library):
    shape = load_shape("sym_cube", library_dirs=[str(sym_cube_library)])
    G = shape_symmetries(shape)
    assert len(G) == 24
    _is_group(G)
    # every symmetry maps the facet normals onto the facet normals (independent check)
    n = shape.normals_body
    for R in G:
        d = (n @ R.T) @ n.T
        assert np.allclose(np.sort(d.max(axis=1)), 1.0, atol=1e-9)


def test_rocket_body_symmetries_leave_the_predicted_magnitude_unchanged():
    """Attitudes A and G·A give the same magnitude (the module's claim): evaluate the facet
    model at a random geometry for A and every G·A of the rocket body, through the package's magnitude function,
    and a rotation that is not a symmetry changes it."""
    from lightcurve.photometry.magnitude import apparent_magnitude

    shape = load_shape("rocket_body")
    gq = symmetry_quaternions(shape)
    rng = np.random.default_rng(5)
    q = rot.quat_normalize(rng.standard_normal(4))
    s = rng.standard_normal(3)
    o = rng.standard_normal(3)
    s, o = s / np.linalg.norm(s), o / np.linalg.norm(o)
    Q = rot.quat_mult(gq, np.broadcast_to(q, gq.shape))[None]        # (1, K, 4)
    m = apparent_magnitude(shape, Q, s[None], o[None], np.array([7.0e5]),
                           np.array([1.496e11]))[0]
    assert np.isfinite(m[0])
    assert np.allclose(m, m[0], atol=1e-9)
    # a rotation that is not a symmetry (10° about x) changes it
    q_x = rot.quat_mult(rot.rotvec_to_quat(np.radians([10.0, 0.0, 0.0])), q)
    m_x = apparent_magnitude(shape, q_x[None], s[None], o[None], np.array([7.0e5]),
                             np.array([1.496e11]))[0]
    assert abs(m_x - m[0]) > 1e-3


def test_error_modulo_symmetry_and_folding():
    shape = load_shape("rocket_body")
    G = shape_symmetries(shape)
    gq = symmetry_quaternions(shape)
    rng = np.random.default_rng(1)
    q = rot.quat_normalize(rng.standard_normal(4))
    q_img = rot.quat_mult(gq[7], q)
    # raw error ≥ 36° (a D₁₀ rotation), modulo the group 0
    assert np.degrees(rot.attitude_error_angle(q, q_img)) > 35.0
    assert error_modulo_symmetry(q, q_img, G) < 1e-6
    # a small perturbation survives the modulo
    q_off = rot.quat_mult(rot.rotvec_to_quat(np.radians([3.0, 0.0, 0.0])), q_img)
    assert error_modulo_symmetry(q, q_off, G) == pytest.approx(3.0, abs=1e-6)
    # folding every image onto the reference returns the reference itself, rates rotated back
    w = np.array([0.1, -0.2, 0.05])
    Q = rot.quat_mult(gq, np.broadcast_to(q, gq.shape))
    W = np.einsum("nij,j->ni", G, w)
    Qf, Wf, k = fold_to_reference(Q, W, q, gq)
    assert np.allclose(np.abs(Qf @ q), 1.0, atol=1e-12)
    assert np.allclose(Wf, w, atol=1e-12)
