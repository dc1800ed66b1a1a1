"""The numba kernels of the study speed path against their NumPy oracles.

* filters: ``ControlledDynamics.transition`` / ``UncontrolledDynamics.transition`` (numba,
  lightcurve/core/dynamics.py) against the NumPy oracles of tests/transition_oracle.py (scipy
  ``expm`` Van Loan, ``np.linalg.solve``), and the kernels ``error_F_nb`` /
  ``van_loan_nb`` against ``error_F`` / ``discretize``; random states, fixed seeds, agreement
  to 1e-12 relative to the largest entry (both compute the same formulas; the difference is
  rounding, measured ≤ 1e-13).
* dynamics: the one-state gravity-gradient fast path of ``GravityGradientTorque.torque`` against
  ``gravity_gradient_torque`` (Bernard eq. 4.20, NumPy), and the truth model's right-hand side
  against ``rigid_body.state_derivative`` (eq. 4.12–4.13).
"""

from __future__ import annotations

import numpy as np
import pytest

from lightcurve.dynamics.rigid_body import state_derivative
from lightcurve.dynamics.torques import GravityGradientTorque, gravity_gradient_torque
from transition_oracle import (controlled_transition_numpy, discretize, error_F,
                               uncontrolled_transition_numpy)

from lightcurve.core import dynamics as TK
from lightcurve.filters.models import ControlledDynamics, UncontrolledDynamics

TOL = 1e-12


def _rel(a, b):
    scale = max(np.max(np.abs(b)), 1e-300)
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / scale)


def _inertia(rng):
    A = rng.normal(size=(3, 3))
    return A @ A.T + 2.0 * np.eye(3)  # symmetric positive definite, kg m²


def _random_cases(seed, n):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        J = _inertia(rng)
        # rates from the thesis fast spin (≈ 0.07 rad/s) down to 1e-9 rad/s (small-angle branch)
        w = rng.normal(size=3) * rng.choice([1e-10, 1e-3, 0.07, 0.3])
        dt = float(rng.choice([0.05, 1.0, 5.0, 7.3, -2.0]))
        yield rng, J, w, dt


def test_uncontrolled_transition_kernel_matches_numpy_path():
    worst_phi = worst_q = 0.0
    for rng, J, w, dt in _random_cases(701, 60):
        eta = float(rng.choice([0.0, 1e-9, 1e-4]))
        sub = float(rng.choice([0.5, 1.3]))
        d = UncontrolledDynamics(J, eta_psd=eta, substep_s=sub)
        P1, Q1 = d.transition(w, dt)
        P0, Q0 = uncontrolled_transition_numpy(J, eta, sub, w, dt)
        worst_phi = max(worst_phi, _rel(P1, P0))
        if eta > 0:
            assert np.max(np.abs(Q0)) > 0
            worst_q = max(worst_q, _rel(Q1, Q0))
        else:
            assert np.all(Q1 == 0.0)
    assert worst_phi < TOL and worst_q < TOL, (worst_phi, worst_q)
    d = UncontrolledDynamics(np.diag([1.0, 2.0, 3.0]), eta_psd=1e-6)
    P, Q = d.transition(np.ones(3), 0.0)
    assert np.array_equal(P, np.eye(6)) and np.array_equal(Q, np.zeros((6, 6)))


def test_controlled_transition_kernel_matches_numpy_path():
    worst = 0.0
    for rng, _J, w, dt in _random_cases(702, 60):
        pn = float(rng.choice([0.0, 1e-7]))
        c = ControlledDynamics(acs_sigma_rad=1e-3, pseudo_noise=pn)
        P1, Q1 = c.transition(w, dt)
        P0, Q0 = controlled_transition_numpy(w, dt, pn)
        worst = max(worst, _rel(P1, P0))
        if pn > 0:
            worst = max(worst, _rel(Q1, Q0))
        else:
            assert np.all(Q1 == 0.0)
    assert worst < TOL, worst


def test_error_F_and_van_loan_kernels_match_scipy():
    rng = np.random.default_rng(703)
    for _ in range(30):
        J = _inertia(rng)
        w = rng.normal(size=3) * 0.2
        F = np.empty((6, 6))
        TK.error_F_nb(w, J, np.linalg.inv(J), True, F)
        assert _rel(F, error_F(w, J)) < TOL
        TK.error_F_nb(w, J, np.linalg.inv(J), False, F)
        assert _rel(F, error_F(w)) < TOL
        # a general (non-structured) F and PSD Qc, and steps that need scaling and squaring
        # (‖F Δt‖₁ up to ≈ 5; much longer steps of this unstable random F make Van Loan's
        # Q_d = Φ E₁₂ ill-conditioned — both methods then lose digits, see the report)
        Fg = rng.normal(size=(6, 6)) * 0.3
        B = rng.normal(size=(6, 6))
        Qc = B @ B.T * 1e-3
        for dt in (0.1, 1.0, 4.0):
            Phi, Qd = np.empty((6, 6)), np.empty((6, 6))
            TK.van_loan_nb(Fg, Qc, dt, Phi, Qd)
            P0, Q0 = discretize(Fg, Qc, dt)
            assert _rel(Phi, P0) < 1e-11, (dt, _rel(Phi, P0))
            assert _rel(Qd, Q0) < 1e-11, (dt, _rel(Qd, Q0))
            assert np.array_equal(Qd, Qd.T)


def test_gravity_gradient_fast_path_matches_numpy():
    rng = np.random.default_rng(704)
    J = np.diag([0.02, 0.025, 0.03]) + 0.001
    r_of_t = lambda t: np.array([6871.14e3 * np.cos(1e-3 * t), 6871.14e3 * np.sin(1e-3 * t), 1e5])
    gg = GravityGradientTorque(J, r_of_t)
    worst = 0.0
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        t = float(rng.uniform(0, 400))
        T1 = gg.torque(t, q)
        T0 = gravity_gradient_torque(r_of_t(t), q, J)
        assert T1.shape == (3,)
        worst = max(worst, _rel(T1, T0))
    assert worst < TOL, worst
    # a stack of attitudes still goes through the validating NumPy function
    Q = rng.normal(size=(5, 4))
    Q /= np.linalg.norm(Q, axis=1, keepdims=True)
    assert gg.torque(1.0, Q).shape == (5, 3)
    with pytest.raises(ValueError):
        GravityGradientTorque(J, np.zeros(3)).torque(0.0, np.array([1.0, 0, 0, 0]))


def test_truth_rhs_kernel_matches_state_derivative():
    from lightcurve.dynamics.truth import _truth_rhs_nb

    rng = np.random.default_rng(705)
    for _ in range(40):
        J = _inertia(rng)
        x = rng.normal(size=7)
        T = rng.normal(size=3) * 1e-6
        eta = rng.normal(size=3) * 1e-5
        ref = state_derivative(0.0, x, J, torque_fn=lambda t, q, w: T)
        ref[4:] += eta
        assert _rel(_truth_rhs_nb(x, T, J, np.linalg.inv(J), eta), ref) < TOL


def test_non_finite_rate_refused():
    for d in (UncontrolledDynamics(np.diag([1.0, 2.0, 3.0])), ControlledDynamics()):
        with pytest.raises(ValueError, match="NaN or infinite"):
            d.transition([np.nan, 0.0, 0.0], 1.0)
