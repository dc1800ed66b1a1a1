"""Bernard (2021) eq. 4.16–4.21 torques in the thesis's forms, and the single-state kernels.

* SRP (eq. 4.16–4.19) with R_d = ξ, R_s = 1 − ξ (eq. 4.17–4.18): an independent per-facet
  NumPy evaluation of eq. 4.16/4.19 written here equals the package's torque.
* Drag (eq. 4.21, 4.23) along the facet normal with the orbital velocity: the same check; for
  the cube (centres of pressure on the normals) the torque is exactly zero.
* The numba single-state kernels used by the truth integrator equal the validating NumPy
  functions for random states (both drag forms).
"""

from __future__ import annotations

import numpy as np
import pytest

from lightcurve.dynamics.atmosphere import altitude_m, density_kg_m3
from lightcurve.dynamics.torques import (AU_M, P_SUN_1AU, DragTorque, SRPTorque, drag_torque,
                                         drag_torque_nb, srp_torque, srp_torque_nb)
from lightcurve.dynamics.truth import srp_coefficients_thesis
from lightcurve.photometry import load_shape
from lightcurve.rotations import quat_rotate


def _rand_q(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _A(q):
    q1, q2, q3, q4 = q
    v = np.array([q2, q3, q4])
    S = np.array([[0, -q4, q3], [q4, 0, -q2], [-q3, q2, 0]])
    return (q1 ** 2 - v @ v) * np.eye(3) + 2 * np.outer(v, v) - 2 * q1 * S


def test_srp_thesis_reflectivities_and_eq_4_16():
    cube = load_shape("cube_1u")
    Rs, Rd = srp_coefficients_thesis(cube.materials)
    xi = cube.facet_params("xi")
    np.testing.assert_array_equal(Rd, xi)
    np.testing.assert_array_equal(Rs, 1.0 - xi)
    rng = np.random.default_rng(3)
    centers = cube.centers_body_m + rng.normal(scale=0.01, size=(6, 3))  # off the normal lines
    for q in _rand_q(rng, 20):
        s = rng.normal(size=3)
        s /= np.linalg.norm(s)
        sb = _A(q) @ s
        ref = np.zeros(3)
        for i in range(6):
            n = cube.normals_body[i]
            cth = n @ sb
            F = -P_SUN_1AU * cube.areas_m2[i] * (2 * (Rd[i] / 3 + Rs[i] * cth) * n
                                                 + (1 - Rs[i]) * sb) * max(cth, 0.0)
            ref += np.cross(centers[i], F)
        got = SRPTorque(cube.areas_m2, cube.normals_body, centers, Rs, Rd, s).torque(0.0, q)
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-22)


def test_drag_along_normal_eq_4_21_and_zero_for_the_cube():
    cube = load_shape("cube_1u")
    rng = np.random.default_rng(4)
    r = np.array([6871.14e3, 0.0, 0.0])
    v = np.array([0.0, 7.6e3, 0.0])
    rho = float(density_kg_m3(altitude_m(r)))
    centers = cube.centers_body_m + rng.normal(scale=0.01, size=(6, 3))
    for q in _rand_q(rng, 20):
        vb = _A(q) @ v
        ref = np.zeros(3)
        for i in range(6):
            n = cube.normals_body[i]
            F = -0.5 * rho * 2.2 * cube.areas_m2[i] * (vb @ vb) * max(vb @ n / np.linalg.norm(vb), 0) * n
            ref += np.cross(centers[i], F)
        got = drag_torque(q, r, v, cube.areas_m2, cube.normals_body, centers, omega_earth=0.0,
                          form="normal")
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-25)
        zero = DragTorque(cube.areas_m2, cube.normals_body, cube.centers_body_m, r, v,
                          omega_earth=0.0, form="normal").torque(0.0, q)
        assert np.all(np.abs(zero) < 1e-22)
    with pytest.raises(ValueError, match="form"):
        drag_torque(q, r, v, cube.areas_m2, cube.normals_body, centers, form="sideways")


def test_single_state_kernels_equal_the_numpy_torques():
    sh = load_shape("box_wing")
    rng = np.random.default_rng(5)
    A, n, c = sh.areas_m2, sh.normals_body, sh.centers_body_m
    cs, cd = rng.uniform(0, 0.5, len(A)), rng.uniform(0, 0.5, len(A))
    r = np.array([7000e3, 100e3, -30e3])
    v = np.array([-100.0, 7500.0, 200.0])
    for q in _rand_q(rng, 30):
        s = rng.normal(size=3)
        s /= np.linalg.norm(s)
        d = 1.01 * AU_M
        P = P_SUN_1AU * (AU_M / d) ** 2 * 0.7
        np.testing.assert_allclose(
            srp_torque_nb(q, s, P, A, n, c, cs, cd),
            srp_torque(q, s, A, n, c, cs, cd, lit_fraction=0.7, sun_distance_m=d),
            rtol=1e-12, atol=1e-25)
        for form, we in (("velocity", 7.292115e-5), ("normal", 0.0)):
            vrel = v - np.cross([0, 0, we], r)
            rc = float(density_kg_m3(altitude_m(r))) * 2.2
            np.testing.assert_allclose(
                drag_torque_nb(q, vrel, rc, A, n, c, form == "normal"),
                drag_torque(q, r, v, A, n, c, omega_earth=we, form=form), rtol=1e-12, atol=1e-25)
    assert np.allclose(quat_rotate(np.array([1.0, 0, 0, 0]), s), s)
