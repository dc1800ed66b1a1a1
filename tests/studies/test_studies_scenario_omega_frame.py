"""``[attitude] omega_frame``: in which axes (body or inertial) a scenario gives its rates
(Bernard 2021 §10.7).

* a bad value, or ``"inertial"`` with a nadir frame, is an InputError naming the key;
* ``"inertial"`` with q0 = identity gives exactly the ``"body"`` result (A(q0) = I);
* ``"inertial"`` converts ω_B = A(q0) ω_I (Bernard eq. 3.16) — checked against an independent
  plain-numpy eq. 3.7 (3-2-1 DCM) and against an independently measured ω_B = [−2.680, 3.282,
  0.088] °/s for the LEO fast-spin angles;
* property (hypothesis): for a torque-free isotropic body (uncontrolled, Euler's equations) and
  for the controlled model without ACS noise, the inertial angular velocity recovered by finite
  differences from consecutive truth quaternions, ω_I = θ ê / Δt with
  R_Δ = A_{k+1}ᵀ A_k = exp(Δt [ω_I×]) (body axes expressed in inertial axes turn by R_Δ), equals
  the ω_I written in the file. Independent re-implementation: eq. 3.16 and the rotation-matrix
  logarithm written out here, not lightcurve.rotations.
* the default reading ("body") is unchanged bit for bit (the thesis file's truth).
"""

from __future__ import annotations

import tomllib
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.studies.scenario import load_scenario, parse_scenario
from lightcurve.studies.simulate import truth_attitude

THESIS = data_dir("pipelines") / "thesis"
BASE = THESIS / "leo-ic1-fast-spin-controlled-1site.toml"


def A_of_q(q):
    """Bernard eq. 3.16 (inertial→body attitude matrix), written out independently."""
    q1, q2, q3, q4 = q
    v = np.array([q2, q3, q4])
    S = np.array([[0, -q4, q3], [q4, 0, -q2], [-q3, q2, 0]])
    return (q1**2 - v @ v) * np.eye(3) + 2 * np.outer(v, v) - 2 * q1 * S


def A_321(phi, theta, psi):
    """Bernard eq. 3.7: A = R1(ψ) R2(θ) R3(φ), passive, angles in rad (independent)."""
    c, s = np.cos, np.sin
    R3 = np.array([[c(phi), s(phi), 0], [-s(phi), c(phi), 0], [0, 0, 1]])
    R2 = np.array([[c(theta), 0, -s(theta)], [0, 1, 0], [s(theta), 0, c(theta)]])
    R1 = np.array([[1, 0, 0], [0, c(psi), s(psi)], [0, -s(psi), c(psi)]])
    return R1 @ R2 @ R3


def log_rotvec(R):
    """Rotation vector θ ê of an active rotation matrix R (angle < π), plain numpy."""
    ang = np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))
    w = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return w if ang < 1e-12 else w * ang / np.sin(ang)


def _doc(**attitude):
    doc = tomllib.loads(BASE.read_text())
    doc["attitude"].update(attitude)
    return doc


def test_bad_omega_frame_names_key():
    with pytest.raises(InputError) as ei:
        parse_scenario(_doc(omega_frame="orbit"), file="x.toml")
    assert ei.value.field == "attitude.omega_frame"
    assert "body" in str(ei.value) and "inertial" in str(ei.value) and "x.toml" in str(ei.value)


def test_inertial_rates_with_nadir_frame_refused():
    with pytest.raises(InputError) as ei:
        parse_scenario(_doc(omega_frame="inertial", frame="nadir"), file="n.toml")
    assert ei.value.field == "attitude.omega_frame" and "n.toml" in str(ei.value)
    # the body reading with nadir keeps working
    sc = parse_scenario(_doc(omega_frame="body", frame="nadir"), file="n.toml")
    assert sc.attitude.omega_frame == "body"


def test_identity_q0_inertial_equals_body():
    w = [2.0, -1.5, 3.6]
    a = parse_scenario(_doc(euler321_deg=[0.0, 0.0, 0.0], omega_deg_s=w), file="a.toml")
    b = parse_scenario(_doc(euler321_deg=[0.0, 0.0, 0.0], omega_deg_s=w, omega_frame="inertial"),
                       file="b.toml")
    assert np.array_equal(a.attitude.omega_deg_s, b.attitude.omega_deg_s)
    t = np.arange(0.0, 60.0, 5.0)
    qa, wa = truth_attitude(a, t, np.random.default_rng(3))
    qb, wb = truth_attitude(b, t, np.random.default_rng(3))
    assert np.array_equal(qa, qb) and np.array_equal(wa, wb)


def test_default_body_reading_unchanged():
    """No key = "body": the parsed rates are the file's numbers, the truth unchanged bit for bit."""
    a = load_scenario(BASE)
    b = parse_scenario(_doc(omega_frame="body"), file=str(BASE))
    assert a.attitude.omega_frame == "body"
    assert np.array_equal(a.attitude.omega_deg_s, [2.0, 1.0, 3.6])
    t = np.arange(0.0, 361.0, 5.0)
    qa, _ = truth_attitude(a, t, np.random.default_rng(1))
    qb, _ = truth_attitude(b, t, np.random.default_rng(1))
    assert np.array_equal(qa, qb)


def test_thesis_inertial_rates_conversion():
    sc = parse_scenario(_doc(omega_frame="inertial"), file="inertial-rates.toml")
    at = sc.attitude
    assert at.omega_frame == "inertial"
    assert np.array_equal(at.omega_input_deg_s, [2.0, 1.0, 3.6])
    A0 = A_321(*np.radians([-42.4122, 59.1601, 48.9897]))
    np.testing.assert_allclose(at.omega_deg_s, A0 @ np.array([2.0, 1.0, 3.6]), atol=1e-12)
    # independently measured numbers for this reading (3 decimals)
    np.testing.assert_allclose(at.omega_deg_s, [-2.680, 3.282, 0.088], atol=6e-4)
    # the rest equals the thesis file
    base = load_scenario(BASE)
    assert np.array_equal(base.attitude.euler321_deg, at.euler321_deg)
    assert base.epoch_utc == sc.epoch_utc and base.duration_s == sc.duration_s


def _inertial_omega_fd(q, dt):
    """ω_I (rad/s) per interval from consecutive quaternions: R_Δ = A_{k+1}ᵀ A_k."""
    return np.array([log_rotvec(A_of_q(q[k + 1]).T @ A_of_q(q[k])) / dt for k in range(len(q) - 1)])


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(angles=st.lists(st.floats(-179.0, 179.0), min_size=3, max_size=3),
       w=st.lists(st.floats(-6.0, 6.0), min_size=3, max_size=3),
       dynamics=st.sampled_from(["uncontrolled", "controlled"]))
def test_truth_turns_about_given_inertial_omega(angles, w, dynamics):
    angles[1] = float(np.clip(angles[1], -89.0, 89.0))
    extra = ({"torques": [], "eta_sigma_deg_s2": 0.0,
              "inertia_kg_m2": [[0.002, 0, 0], [0, 0.002, 0], [0, 0, 0.002]]}
             if dynamics == "uncontrolled" else {"acs_sigma_deg": 0.0})
    doc = _doc(dynamics=dynamics, euler321_deg=angles, omega_deg_s=w, omega_frame="inertial",
               **extra)
    sc = parse_scenario(doc, file="p.toml")
    dt = 2.0  # |ω| ≤ 10.4 °/s → ≤ 21° per step, well inside the log's range
    t = np.arange(0.0, 40.0 + dt / 2, dt)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        q, _ = truth_attitude(sc, t, np.random.default_rng(0))
    np.testing.assert_allclose(A_of_q(q[0]), A_321(*np.radians(angles)), atol=1e-9)
    wI = _inertial_omega_fd(q, dt)
    # DOP853 at rtol 1e-12 over 40 s; the controlled model is exact up to rounding
    np.testing.assert_allclose(wI, np.broadcast_to(np.radians(w), wI.shape), atol=1e-8)


def test_body_reading_is_not_inertial():
    """Positive control: with the thesis angles the two readings give different inertial axes
    (the finite-difference check above would catch a conversion that did nothing)."""
    base = load_scenario(BASE)
    t = np.arange(0.0, 21.0, 1.0)
    sc = parse_scenario(_doc(acs_sigma_deg=0.0), file="c.toml")
    q, _ = truth_attitude(sc, t, np.random.default_rng(0))
    wI = _inertial_omega_fd(q, 1.0)
    assert np.max(np.abs(wI - np.radians([2.0, 1.0, 3.6]))) > np.radians(1.0)
    # ... and in the body reading the inertial ω is A(q0)ᵀ ω_B, constant
    A0 = A_321(*np.radians(base.attitude.euler321_deg))
    np.testing.assert_allclose(wI, np.broadcast_to(A0.T @ np.radians([2.0, 1.0, 3.6]), wI.shape),
                               atol=1e-10)
