"""Environmental torques (Bernard 2021 eq. 4.16–4.23) and the exponential atmosphere."""

import numpy as np
import pytest

from lightcurve import rotations as rot
from lightcurve.dynamics import (
    AU_M,
    EXPONENTIAL_TABLE,
    MU_EARTH,
    OMEGA_EARTH,
    P_SUN_1AU,
    R_EARTH_M,
    ConstantTorque,
    DragTorque,
    GravityGradientTorque,
    SRPTorque,
    TorqueSum,
    density_kg_m3,
    drag_torque,
    gravity_gradient_torque,
    gravity_gradient_torque_nb,
    srp_torque,
)

Q = rot.euler321_to_quat(np.radians([30.0, -20.0, 75.0]))
I4 = np.array([1.0, 0, 0, 0])


# ---------------------------------------------------------------------------- atmosphere
def test_atmosphere_table_values_at_band_bases():
    # Vallado (2013) Table 8-4 / Markley & Crassidis exponential atmosphere: ρ(h0) = ρ0.
    for h0_km, rho0, _ in EXPONENTIAL_TABLE:
        assert density_kg_m3(h0_km * 1e3) == pytest.approx(rho0, rel=1e-12)
    # spot values typed independently from the table (400 km: 3.725e-12, 800 km: 1.170e-14)
    assert density_kg_m3(400e3) == pytest.approx(3.725e-12, rel=1e-12)
    assert density_kg_m3(800e3) == pytest.approx(1.170e-14, rel=1e-12)
    # inside a band: ρ0 exp(−Δh/H); 420 km in the 400–450 km band (H = 58.515 km)
    assert density_kg_m3(420e3) == pytest.approx(3.725e-12 * np.exp(-20 / 58.515), rel=1e-12)


def test_atmosphere_table_internally_consistent():
    # The table's scale heights were fitted so that each band meets the next band's base
    # density; a typo in any ρ0 or H would show up as a jump (largest genuine one: 0.14 % at 25 km).
    h = EXPONENTIAL_TABLE[1:, 0] * 1e3
    below = density_kg_m3(h - 1e-6)
    above = density_kg_m3(h)
    assert np.max(np.abs(below / above - 1)) < 2e-3
    hh = np.linspace(0, 1500e3, 3001)
    assert np.all(np.diff(density_kg_m3(hh)) < 0)


def test_atmosphere_vectorised_and_errors():
    h = np.array([[100e3, 200e3], [500e3, 1200e3]])
    assert density_kg_m3(h).shape == (2, 2)
    assert isinstance(density_kg_m3(300e3), float)
    with pytest.raises(ValueError, match="below 0 km"):
        density_kg_m3(-1.0)
    with pytest.raises(ValueError, match="NaN"):
        density_kg_m3([100e3, np.nan])


# ---------------------------------------------------------------------------- gravity gradient
def test_gravity_gradient_matches_point_mass_sum():
    # Independent oracle: a body made of point masses; the exact torque Σ ρ_i × F_i with
    # F_i = −μ m_i R_i/|R_i|³ agrees with 3μ/r³ r̂ × J r̂ (Bernard eq. 4.20) to O(|ρ|/r).
    pts = np.array([[2.0, 0, 0], [-2.0, 0, 0], [0, 1.5, 0.3], [0, -1.5, -0.3], [0.2, 0, 1.0], [-0.2, 0, -1.0]])
    m = np.array([30.0, 30.0, 50.0, 50.0, 80.0, 80.0])  # symmetric pairs: centre of mass at 0
    J = sum(mi * (p @ p * np.eye(3) - np.outer(p, p)) for mi, p in zip(m, pts))
    r = np.array([4.1e6, -3.3e6, 4.2e6])
    A = rot.quat_to_dcm(Q)
    exact = np.zeros(3)
    for mi, p in zip(m, pts):
        R = r + A.T @ p
        F_b = A @ (-MU_EARTH * mi * R / np.linalg.norm(R) ** 3)
        exact += np.cross(p, F_b)
    T = gravity_gradient_torque(r, Q, J)
    assert np.linalg.norm(T - exact) < 1e-5 * np.linalg.norm(T)
    assert np.linalg.norm(T) > 1e-6  # not a trivially zero configuration


def test_gravity_gradient_zero_along_principal_axes_and_vectorised():
    J = np.diag([10.0, 20.0, 30.0])
    for axis in np.eye(3):
        assert np.allclose(gravity_gradient_torque(7e6 * axis, I4, J), 0.0, atol=1e-20)
    r = np.array([[7e6, 1e5, 2e5], [1e6, -6.9e6, 3e5]])
    q = np.stack([Q, I4])
    T = gravity_gradient_torque(r, q, J)
    for i in range(2):
        np.testing.assert_allclose(T[i], gravity_gradient_torque(r[i], q[i], J), rtol=1e-14)
    for i in range(2):  # numba kernel agrees with the numpy layer
        np.testing.assert_allclose(gravity_gradient_torque_nb(q[i], r[i], J, MU_EARTH), T[i], rtol=1e-13)
    model = GravityGradientTorque(J, lambda t: r[0])
    np.testing.assert_allclose(model.torque(0.0, Q), gravity_gradient_torque(r[0], Q, J))


# ---------------------------------------------------------------------------- SRP
PLATE = dict(areas_m2=np.array([2.0]), normals_body=np.array([[1.0, 0, 0]]),
             centers_body_m=np.array([[0.0, 0.5, 0.0]]))


@pytest.mark.parametrize("cs, cd, factor_s, factor_n", [
    (0.0, 0.0, 1.0, 0.0),        # absorber: F = −P A ŝ
    (1.0, 0.0, 0.0, 2.0),        # mirror at normal incidence: F = −2 P A n̂
    (0.0, 1.0, 1.0, 2.0 / 3.0),  # Lambertian: F = −P A (ŝ + 2/3 n̂)
])
def test_srp_flat_plate_normal_incidence(cs, cd, factor_s, factor_n):
    # Markley & Crassidis §3.3.6 flat-plate SRP force, limiting cases.
    s = np.array([1.0, 0, 0])
    F = -P_SUN_1AU * 2.0 * (factor_s * s + factor_n * np.array([1.0, 0, 0]))
    T = srp_torque(I4, s, c_spec=cs, c_diff=cd, **PLATE)
    np.testing.assert_allclose(T, np.cross([0.0, 0.5, 0.0], F), rtol=1e-14, atol=1e-25)
    assert np.linalg.norm(T) > 0


def test_srp_oblique_specular_and_geometry_rules():
    # mirror at 60° incidence: F = −2 P A cos²θ n̂ (only the normal component survives)
    s = np.array([np.cos(np.radians(60)), np.sin(np.radians(60)), 0.0])
    T = srp_torque(I4, s, c_spec=1.0, c_diff=0.0, **PLATE)
    F = -2 * P_SUN_1AU * 2.0 * 0.25 * np.array([1.0, 0, 0])
    np.testing.assert_allclose(T, np.cross([0, 0.5, 0], F), rtol=1e-12)
    # back-lit facet: no force
    assert np.all(srp_torque(I4, -s, c_spec=0.3, c_diff=0.3, **PLATE) == 0)
    # eclipse and partial lighting scale linearly; pressure ∝ (1 au / d)²
    T1 = srp_torque(I4, s, c_spec=0.2, c_diff=0.5, **PLATE)
    assert np.all(srp_torque(I4, s, c_spec=0.2, c_diff=0.5, lit_fraction=0.0, **PLATE) == 0)
    np.testing.assert_allclose(srp_torque(I4, s, c_spec=0.2, c_diff=0.5, lit_fraction=0.4, **PLATE), 0.4 * T1, rtol=1e-14)
    np.testing.assert_allclose(srp_torque(I4, s, c_spec=0.2, c_diff=0.5, sun_distance_m=2 * AU_M, **PLATE), T1 / 4, rtol=1e-14)
    # frame consistency: rotating the Sun into body axes by hand gives the same torque
    s_I = np.array([0.2, -0.5, 0.84])
    s_I /= np.linalg.norm(s_I)
    np.testing.assert_allclose(srp_torque(Q, s_I, c_spec=0.2, c_diff=0.5, **PLATE),
                               srp_torque(I4, rot.quat_rotate(Q, s_I), c_spec=0.2, c_diff=0.5, **PLATE), rtol=1e-13)


def test_srp_bad_inputs():
    s = np.array([1.0, 0, 0])
    with pytest.raises(ValueError, match="must not exceed 1"):
        srp_torque(I4, s, c_spec=0.7, c_diff=0.5, **PLATE)
    with pytest.raises(ValueError, match="sum to 1"):
        srp_torque(I4, s, c_spec=0.2, c_diff=0.5, c_abs=0.1, **PLATE)
    with pytest.raises(ValueError, match="lit_fraction"):
        srp_torque(I4, s, c_spec=0.2, c_diff=0.5, lit_fraction=1.5, **PLATE)
    with pytest.raises(ValueError, match="normals_body: not a unit"):
        srp_torque(I4, s, c_spec=0.2, c_diff=0.5, areas_m2=[1.0], normals_body=[[2.0, 0, 0]], centers_body_m=[[0, 0, 0]])
    with pytest.raises(ValueError, match="centers_body_m.*shape"):
        srp_torque(I4, s, c_spec=0.2, c_diff=0.5, areas_m2=[1.0, 1.0], normals_body=[[1.0, 0, 0]] * 2, centers_body_m=[[0, 0, 0]])
    with pytest.raises(ValueError, match="sun_dir_eci"):
        srp_torque(I4, [1.0, 1.0, 0], c_spec=0.2, c_diff=0.5, **PLATE)


# ---------------------------------------------------------------------------- drag
def test_drag_flat_plate_ram_and_corotation():
    # F = −½ ρ C_D A |v|² cos α v̂ (Markley & Crassidis §3.3.6 flat-plate drag); plate facing the flow.
    r = np.array([R_EARTH_M + 400e3, 0.0, 0.0])
    v = np.array([0.0, 7668.0, 0.0])
    plate = dict(areas_m2=[3.0], normals_body=[[0.0, 1.0, 0.0]], centers_body_m=[[0.4, 0.0, 0.1]])
    rho = 3.725e-12
    T = drag_torque(I4, r, v, Cd=2.2, omega_earth=0.0, **plate)
    F = -0.5 * rho * 2.2 * 3.0 * 7668.0**2 * np.array([0, 1.0, 0])
    np.testing.assert_allclose(T, np.cross([0.4, 0, 0.1], F), rtol=1e-12)
    # co-rotating atmosphere: relative speed v − ω_E |r| along ŷ here
    vr = 7668.0 - OMEGA_EARTH * r[0]
    F2 = -0.5 * rho * 2.2 * 3.0 * vr**2 * np.array([0, 1.0, 0])
    np.testing.assert_allclose(drag_torque(I4, r, v, **plate), np.cross([0.4, 0, 0.1], F2), rtol=1e-12)
    # 60° between normal and flow: force ∝ cos α along −v̂
    plate60 = dict(plate, normals_body=[[np.sin(np.radians(60)), np.cos(np.radians(60)), 0.0]])
    F3 = 0.5 * F
    np.testing.assert_allclose(drag_torque(I4, r, v, omega_earth=0.0, **plate60),
                               np.cross([0.4, 0, 0.1], F3), rtol=1e-12)
    # leeward facet: nothing
    leeward = dict(plate, normals_body=[[0.0, -1.0, 0.0]])
    assert np.all(drag_torque(I4, r, v, **leeward) == 0)
    # rotated body: same as rotating the flow into body axes by hand
    vb = rot.quat_rotate(Q, v)
    exp_T = np.cross([0.4, 0, 0.1], -0.5 * rho * 2.2 * 3.0 * max(vb[1], 0) * vb)
    np.testing.assert_allclose(drag_torque(Q, r, v, omega_earth=0.0, **plate), exp_T, rtol=1e-12)
    model = DragTorque(position=r, velocity=v, omega_earth=0.0, **plate)
    np.testing.assert_allclose(model.torque(5.0, Q), exp_T, rtol=1e-12)


def test_torque_sum_and_constant():
    J = np.diag([10.0, 20.0, 30.0])
    r = np.array([7e6, 1e6, -2e6])
    s = np.array([0.0, 0.6, 0.8])
    gg = GravityGradientTorque(J, r)
    srp = SRPTorque(c_spec=0.3, c_diff=0.4, sun_dir=s, **PLATE)
    c = ConstantTorque([1e-6, 0, -1e-6])
    tot = TorqueSum([gg, srp, c])
    np.testing.assert_allclose(tot.torque(0.0, Q), gg.torque(0.0, Q) + srp.torque(0.0, Q) + [1e-6, 0, -1e-6])
    np.testing.assert_allclose(tot.dtheta(0.0, Q), gg.dtheta(0.0, Q) + srp.dtheta(0.0, Q))
