"""Truth models: controlled (Bernard 2021 eq. 7.8–7.11) and uncontrolled (torques + η)."""

import numpy as np
import pytest
from scipy.stats import chi2

from lightcurve import rotations as rot
from lightcurve.dynamics import (
    MU_EARTH,
    ControlledTruth,
    GravityGradientTorque,
    UncontrolledTruth,
    eta_noise_covariance,
    integrate_truth,
    propagate_constant_rate,
    state_derivative,
)

Q0 = rot.euler321_to_quat(np.radians([-42.4122, 59.1601, 48.9897]))
W0 = np.array([0.012, -0.031, 0.02])
J = np.array([[12.0, 0.8, -0.5], [0.8, 21.0, 1.1], [-0.5, 1.1, 30.0]])
ALPHA = 1e-3  # two-sided false-alarm rate of every chi-square test below


def _chi2_ok(stat, dof):
    return chi2.ppf(ALPHA / 2, dof) < stat < chi2.ppf(1 - ALPHA / 2, dof)


def test_controlled_without_noise_is_exact_constant_rate():
    t = np.linspace(0, 300, 31)
    q, w = ControlledTruth(Q0, W0, 0.0, rng=1).simulate(t)
    np.testing.assert_allclose(w, np.tile(W0, (31, 1)))
    qe = propagate_constant_rate(Q0, W0, t - t[0])
    assert np.max(rot.attitude_error_angle(q, qe)) < 1e-12


def test_controlled_random_walk_increments_are_zeta():
    # Each step is q_k = exp(ζ_k) ⊗ exp(ω Δt) ⊗ q_{k−1}, ζ_k ~ N(0, σ² I₃): recover ζ_k exactly
    # and check Σ|ζ_k|²/σ² ~ χ²(3N) and the absence of lag-1 correlation.
    sigma = 2e-3
    t = np.cumsum(np.r_[0.0, np.full(1999, 5.0)])
    q, w = ControlledTruth(Q0, W0, sigma, rng=np.random.default_rng(11)).simulate(t)
    pred = propagate_constant_rate(q[:-1], W0, 5.0)
    zeta = rot.quat_to_rotvec(rot.quat_mult(q[1:], rot.quat_conj(pred)))
    assert _chi2_ok(np.sum(zeta**2) / sigma**2, zeta.size)
    r1 = np.sum(zeta[1:] * zeta[:-1]) / np.sum(zeta**2)
    assert abs(r1) < 3.3 / np.sqrt(zeta.size)  # |N(0,1/n)| bound, false alarm ~1e-3
    assert np.all(zeta[0] != 0) and np.all(rot.quat_to_rotvec(rot.quat_mult(q[0], rot.quat_conj(Q0))) == 0)


def test_controlled_random_walk_accumulates_and_jitter_does_not():
    # Random walk: error after k steps has covariance kσ² I (the body-frame rotation by the
    # constant rate leaves an isotropic covariance unchanged). Jitter: σ² I at every time.
    sigma, k = 1e-3, 40
    t = np.arange(k + 1) * 2.0
    rng = np.random.default_rng(5)
    nominal = propagate_constant_rate(Q0, W0, t)
    end_rw, all_j = [], []
    for _ in range(150):
        q, _ = ControlledTruth(Q0, W0, sigma, rng=rng).simulate(t)
        end_rw.append(rot.quat_to_rotvec(rot.quat_mult(q[-1], rot.quat_conj(nominal[-1]))))
        qj, _ = ControlledTruth(Q0, W0, sigma, rng=rng, mode="jitter").simulate(t)
        all_j.append(rot.quat_to_rotvec(rot.quat_mult(qj[1:], rot.quat_conj(nominal[1:]))))
    end_rw = np.array(end_rw)
    all_j = np.array(all_j)
    assert _chi2_ok(np.sum(end_rw**2) / (k * sigma**2), end_rw.size)
    assert _chi2_ok(np.sum(all_j**2) / sigma**2, all_j.size)


def test_controlled_reproducible_and_validated():
    t = np.arange(10.0)
    a = ControlledTruth(Q0, W0, 1e-3, rng=42).simulate(t)
    b = ControlledTruth(Q0, W0, 1e-3, rng=42).simulate(t)
    c = ControlledTruth(Q0, W0, 1e-3, rng=43).simulate(t)
    np.testing.assert_array_equal(a[0], b[0])
    assert np.any(a[0] != c[0])
    with pytest.raises(ValueError, match="unit"):
        ControlledTruth([1.0, 0.1, 0, 0], W0, 1e-3, rng=1)
    with pytest.raises(ValueError, match="acs_sigma_rad"):
        ControlledTruth(Q0, W0, -1.0, rng=1)
    with pytest.raises(ValueError, match="non-decreasing"):
        ControlledTruth(Q0, W0, 1e-3, rng=1).simulate([0.0, 2.0, 1.0])
    with pytest.raises(ValueError, match="precedes"):
        ControlledTruth(Q0, W0, 1e-3, rng=1, t0_s=5.0).simulate([0.0, 2.0])
    with pytest.raises(ValueError, match="mode"):
        ControlledTruth(Q0, W0, 1e-3, rng=1, mode="other")


def test_uncontrolled_without_noise_matches_integrator_and_conserves():
    t = np.linspace(10.0, 610.0, 13)
    q, w = UncontrolledTruth(Q0, W0, J, rng=0, t0_s=0.0).simulate(t)
    x = integrate_truth(np.r_[Q0, W0], t, lambda tt, xx: state_derivative(tt, xx, J), t0=0.0)
    np.testing.assert_allclose(w, x[:, 4:], atol=1e-13)
    H = rot.quat_rotate_inv(q, w @ J.T)
    assert np.max(np.linalg.norm(H - H[0], axis=1)) < 1e-9 * np.linalg.norm(H[0])


def _lvlh(r, v):
    o3 = -r / np.linalg.norm(r)
    o2 = -np.cross(r, v)
    o2 /= np.linalg.norm(o2)
    return rot.dcm_to_quat(np.array([np.cross(o2, o3), o2, o3]))


@pytest.mark.parametrize("stable", [True, False])
def test_gravity_gradient_lvlh_equilibrium(stable):
    # Circular orbit; body axes = LVLH (x along track, y = −orbit normal, z = nadir), body rate
    # = orbit rate about −y. With J_y > J_x > J_z (max inertia about the orbit normal, the long
    # axis radial: Lagrange region, Hughes "Spacecraft Attitude Dynamics" §9.3) the orientation
    # is an equilibrium and small errors stay small. Swapping J_x and J_z makes pitch unstable
    # (θ̈ = 3n²(J_z − J_x)/J_y θ > 0): the same small error grows by ~e^{2π} per orbit.
    rad = 6878e3
    n = np.sqrt(MU_EARTH / rad**3)
    period = 2 * np.pi / n
    pos = lambda t: rad * np.array([np.cos(n * t), np.sin(n * t), 0.0])  # noqa: E731
    vel = lambda t: rad * n * np.array([-np.sin(n * t), np.cos(n * t), 0.0])  # noqa: E731
    Jd = np.diag([20.0, 30.0, 10.0]) if stable else np.diag([10.0, 30.0, 20.0])
    t = np.linspace(0, period, 41)
    lvlh = np.array([_lvlh(pos(tt), vel(tt)) for tt in t])
    w_lvlh = np.array([0.0, -n, 0.0])
    gg = GravityGradientTorque(Jd, pos)
    if stable:
        q, w = UncontrolledTruth(lvlh[0], w_lvlh, Jd, [gg], rng=0).simulate(t)
        assert np.max(rot.attitude_error_angle(q, lvlh)) < 1e-8
        np.testing.assert_allclose(w, np.tile(w_lvlh, (41, 1)), atol=1e-12)
    # a 1 mrad pitch/roll offset
    dq = rot.rotvec_to_quat([3e-4, 1e-3, 0.0])
    q, w = UncontrolledTruth(rot.quat_mult(dq, lvlh[0]), w_lvlh, Jd, [gg], rng=0).simulate(t)
    err = rot.attitude_error_angle(q, lvlh)
    if stable:
        assert np.max(err) < 3e-3
    else:
        assert np.max(err) > 0.1


def test_uncontrolled_piecewise_constant_eta_statistics():
    # Isotropic J, no torque: ω̇ = η_k exactly, so ω_k − ω_{k−1} = η_k Δt with η_k ~ N(0, σ²I):
    # Σ|Δω|²/(σΔt)² ~ χ²(3N); the same covariance as eta_noise_covariance's δω block.
    sigma, dt, N = 2e-5, 4.0, 400
    t = np.arange(N + 1) * dt
    _, w = UncontrolledTruth(Q0, np.zeros(3), 5.0 * np.eye(3), (), sigma, rng=7,
                             noise="piecewise_constant").simulate(t)
    dw = np.diff(w, axis=0)
    Qd = eta_noise_covariance(dt, sigma, "piecewise_constant")
    assert _chi2_ok(np.sum(dw**2) / Qd[3, 3], dw.size)


def test_uncontrolled_continuous_eta_impulse_covariance():
    # Isotropic J, no torque: the deterministic flow keeps ω constant, so each interval's
    # impulse (δθ, δω) is recovered exactly; its NEES with the discrete covariance
    # σ²[[Δt³/3, Δt²/2],[Δt²/2, Δt]] ⊗ I must be χ²(6N).
    sigma, dt, N = 1e-4, 3.0, 300
    t = np.arange(N + 1) * dt
    q, w = UncontrolledTruth(Q0, W0, 5.0 * np.eye(3), (), sigma, rng=9, noise="continuous").simulate(t)
    pred = propagate_constant_rate(q[:-1], w[:-1], dt)
    dth = rot.quat_to_rotvec(rot.quat_mult(q[1:], rot.quat_conj(pred)))
    dw = np.diff(w, axis=0)
    x = np.concatenate([dth, dw], axis=1)
    Qd = eta_noise_covariance(dt, sigma, "continuous")
    nees = np.einsum("ki,ij,kj->", x, np.linalg.inv(Qd), x)
    assert _chi2_ok(nees, 6 * N)


def test_simultaneous_measurements_share_one_attitude():
    # two sites observing at the same instant see the same truth attitude (one ζ / η draw)
    t = np.array([0.0, 10.0, 10.0, 20.0])
    q, w = ControlledTruth(Q0, W0, 1e-3, rng=3).simulate(t)
    np.testing.assert_array_equal(q[1], q[2])
    assert np.any(q[2] != q[3])
    q, w = UncontrolledTruth(Q0, W0, J, (), 1e-5, rng=3).simulate(t)
    np.testing.assert_array_equal(q[1], q[2])
    np.testing.assert_array_equal(w[1], w[2])
    x = integrate_truth(np.r_[Q0, W0], t, lambda tt, xx: state_derivative(tt, xx, J))
    np.testing.assert_array_equal(x[1], x[2])


def test_uncontrolled_validation():
    with pytest.raises(ValueError, match="positive definite"):
        UncontrolledTruth(Q0, W0, np.diag([1.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="torque_models"):
        UncontrolledTruth(Q0, W0, J, [42])
    with pytest.raises(ValueError, match="noise"):
        UncontrolledTruth(Q0, W0, J, noise="pink")
    with pytest.raises(ValueError, match="omega0_rad_s"):
        UncontrolledTruth(Q0, [np.nan, 0, 0], J)
    with pytest.raises(ValueError, match="rng"):
        UncontrolledTruth(Q0, W0, J, rng="seed")


class _CircularOrbit:
    """Minimal orbit object (the ``positions(epoch_utc, t_s)`` protocol): circular, equatorial."""

    def __init__(self, radius_m):
        self.a = radius_m
        self.n = np.sqrt(MU_EARTH / radius_m**3)

    def positions(self, epoch_utc, t_s):
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        c, s = np.cos(self.n * t), np.sin(self.n * t)
        r = self.a * np.stack([c, s, 0 * t], 1)
        v = self.a * self.n * np.stack([-s, c, 0 * t], 1)
        return r, v


class _Mat:
    def __init__(self, brdf_name, **params):
        self.name, self.brdf_name, self.params = brdf_name, brdf_name, params


class _Shape:
    """A flat plate offset from the centre of mass (so SRP and drag torques do not cancel)."""
    areas_m2 = np.array([2.0, 2.0])
    normals_body = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    centers_body_m = np.array([[1.5, 0.0, 0.2], [1.5, 0.0, 0.2]])
    materials = [_Mat("cook_torrance", xi=0.4, a=0.6, m=0.3), _Mat("lambert", albedo=0.2)]


def test_srp_coefficients_from_materials():
    from lightcurve.dynamics.truth import srp_coefficients_from_materials

    cs, cd = srp_coefficients_from_materials([
        _Mat("cook_torrance", xi=0.4, a=0.6, m=0.3), _Mat("lambert", albedo=0.2),
        _Mat("phong", Kd=0.7, Ks=0.6, n=10), _Mat("ashikhmin_shirley", Rd=0.5, Rs=0.2, nu=1, nv=1)])
    np.testing.assert_allclose(cs, [0.36, 0.0, 0.6 / 1.3, 0.2])
    np.testing.assert_allclose(cd, [0.24, 0.2, 0.7 / 1.3, 0.4])
    with pytest.raises(ValueError, match="no SRP"):
        srp_coefficients_from_materials([_Mat("tabulated:x.csv")])


def test_named_torques_from_orbit_and_shape():
    # Named torques sample the orbit/Sun geometry and interpolate; at any instant they must
    # equal the explicit torque functions evaluated with the exact geometry.
    from lightcurve.dynamics import drag_torque, gravity_gradient_torque, srp_torque
    from lightcurve.geometry.time import sun_position_gcrs

    orb = _CircularOrbit(6778e3)
    epoch = "2020-06-01T00:00:00Z"
    m = UncontrolledTruth(Q0, W0, J, torques=["gravity_gradient", "srp", "drag"], rng=0,
                          shape=_Shape, orbit=orb, epoch_utc=epoch)
    models = m.build_named_torques(0.0, 3000.0)
    assert [type(x).__name__ for x in models] == ["GravityGradientTorque", "DragTorque", "SRPTorque"]
    for tt in (123.4, 1777.7):
        r, v = orb.positions(epoch, tt)
        np.testing.assert_allclose(models[0].torque(tt, Q0), gravity_gradient_torque(r[0], Q0, J), rtol=1e-7)
        Td = drag_torque(Q0, r[0], v[0], _Shape.areas_m2, _Shape.normals_body, _Shape.centers_body_m)
        np.testing.assert_allclose(models[1].torque(tt, Q0), Td, rtol=1e-6)
        rs = sun_position_gcrs(epoch, np.array([tt]))[0]
        rel = rs - r[0]
        from lightcurve.geometry.eclipse import lit_fraction

        lit = float(lit_fraction(r[0], rs)[0])
        Ts = srp_torque(Q0, rel / np.linalg.norm(rel), _Shape.areas_m2, _Shape.normals_body,
                        _Shape.centers_body_m, c_spec=[0.36, 0.0], c_diff=[0.24, 0.2], lit_fraction=lit,
                        sun_distance_m=np.linalg.norm(rel))
        np.testing.assert_allclose(models[2].torque(tt, Q0), Ts, rtol=1e-6, atol=1e-30)
        assert lit == 1.0 and min(np.linalg.norm(x.torque(tt, Q0)) for x in models) > 1e-7
    # the compiled sum the integrator calls is the sum of these models (same splines)
    for tt in (-3.0, 0.0, 20.0, 123.4, 1777.7, 3000.0, 3011.0):
        ref = sum(np.asarray(x.torque(tt, Q0), dtype=float) for x in models)
        np.testing.assert_allclose(m.torque(tt, Q0, W0), ref, rtol=1e-12, atol=0)
    with pytest.raises(ValueError, match="need orbit"):
        UncontrolledTruth(Q0, W0, J, torques=["gravity_gradient"])
    with pytest.raises(ValueError, match="need shape"):
        UncontrolledTruth(Q0, W0, J, torques=["srp"], orbit=orb, epoch_utc=epoch)
    with pytest.raises(ValueError, match="unknown torque"):
        UncontrolledTruth(Q0, W0, J, torques=["magnetic"], orbit=orb, epoch_utc=epoch)


@pytest.mark.parametrize("form", ["velocity", "normal"])
def test_sampled_environment_kernel_equals_the_torque_models(form):
    # Independent re-implementation: environment_torque_nb against the GravityGradientTorque,
    # DragTorque and SRPTorque objects on the same splines (scipy CubicSpline, numpy.interp),
    # at random times inside and outside the samples, at the knots, and across a lit-fraction
    # ramp (penumbra); rounding-level agreement, gravity gradient bit for bit.
    from lightcurve.dynamics.torques import SampledEnvironment, TorqueSum

    rng = np.random.default_rng(7)
    t = np.arange(0.0, 400.1, 20.0)
    w, R = 2 * np.pi / 5600.0, 6.9e6
    r = np.c_[R * np.cos(w * t), R * np.sin(w * t), 1e5 + 0 * t]
    v = np.c_[-R * w * np.sin(w * t), R * w * np.cos(w * t), 0 * t]
    rel = np.c_[1.4e11 + 0 * t, 2e10 + 1e3 * t, 5e9 + 0 * t] - r
    lit = np.clip((t - 100.0) / 60.0, 0.0, 1.0)
    A = np.full(6, 0.01)
    n = np.vstack([np.eye(3), -np.eye(3)])
    c = 0.05 * n + 0.003 * rng.normal(size=(6, 3))
    facets = dict(areas_m2=A, normals_body=n, centers_body_m=c)
    Jc = np.diag([0.002, 0.0025, 0.003])
    env = SampledEnvironment(t, r, v, rel, lit, gravity_gradient=True, J=Jc,
                             drag=dict(facets, form=form, omega_earth=7.292115e-5 if form == "velocity" else 0.0),
                             srp=dict(facets, c_spec=np.full(6, 0.3), c_diff=np.full(6, 0.5)))
    models = env.models()
    assert [type(x).__name__ for x in models] == ["GravityGradientTorque", "DragTorque", "SRPTorque"]
    ref = TorqueSum(models)
    gg = SampledEnvironment(t, r, v, gravity_gradient=True, J=Jc)
    times = np.r_[rng.uniform(-5.0, 405.0, 300), t, 110.0, 130.0]
    for tt in times:
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        T = env.torque(tt, q)
        Tr = ref.torque(tt, q)
        assert np.max(np.abs(T - Tr)) <= 1e-12 * np.max(np.abs(Tr))
        assert np.array_equal(gg.torque(tt, q), models[0].torque(tt, q))
    # in the ramp the SRP term is scaled by the interpolated lit fraction (0.5 at t = 130 s)
    srp_only = SampledEnvironment(t, r, v, rel, lit, srp=dict(facets, c_spec=np.full(6, 0.3),
                                                                c_diff=np.full(6, 0.5)))
    full = SampledEnvironment(t, r, v, rel, np.ones_like(lit), srp=dict(facets, c_spec=np.full(6, 0.3),
                                                                          c_diff=np.full(6, 0.5)))
    np.testing.assert_allclose(srp_only.torque(130.0, Q0), 0.5 * full.torque(130.0, Q0), rtol=1e-12)
    assert np.all(srp_only.torque(90.0, Q0) == 0.0)
    with pytest.raises(ValueError, match="lit"):
        SampledEnvironment(t, r, v, rel, lit + 0.5, srp=dict(facets, c_spec=0.3, c_diff=0.5))
    with pytest.raises(ValueError, match="t_s"):
        SampledEnvironment(t[::-1], r, v)
    with pytest.raises(ValueError, match="strictly increasing"):
        SampledEnvironment(np.r_[t[:2], t[1:]], np.r_[r[:1], r], np.r_[v[:1], v])


def test_named_torque_truth_equals_the_python_torque_path():
    # The truth integrated with the compiled named-torque right-hand side equals the same truth
    # integrated through the torque model objects (the generic Python path), same noise draws.
    orb = _CircularOrbit(6778e3)
    epoch = "2020-06-01T00:00:00Z"
    t = np.arange(0.0, 120.1, 10.0)
    kw = dict(eta_sigma_rad_s2=1e-6, shape=_Shape, orbit=orb, epoch_utc=epoch)
    fast = UncontrolledTruth(Q0, W0, J, torques=["gravity_gradient", "srp", "drag"], rng=3, **kw)
    q1, w1 = fast.simulate(t)
    models = fast.build_named_torques(0.0, float(t[-1]))
    slow = UncontrolledTruth(Q0, W0, J, torque_models=models, rng=3, eta_sigma_rad_s2=1e-6)
    q2, w2 = slow.simulate(t)
    np.testing.assert_allclose(q1, q2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(w1, w2, rtol=0, atol=1e-14)
    assert np.max(np.abs(w1 - W0)) > 1e-6  # the torques and noise moved the rates
