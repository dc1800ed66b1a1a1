"""The one driver loop of the Kalman filters (MEKF, UKF) over a state-space model.

A filter problem (:class:`~lightcurve.filters._common.FilterProblem`) is a state-space model:
the dynamics (``problem.dynamics``: ``propagate(Q, W, dt)``, ``transition(ω, dt) → (Φ, Q_d)``),
the measurement model (``problem.model``: ``predict_q(Q, k)`` vectorised over attitudes,
partials, noise ``σ_k``) and extra states appended to the error state — per-site reflection
biases and Model 3 facet parameters (:class:`~lightcurve.filters._common.StateLayout`); the
interfaces are written down in :mod:`lightcurve.estimation.protocols`. A Kalman filter is a
*step*: how it moves the estimate over Δt (:meth:`KalmanStep.predict`) and how it uses one
measurement (:meth:`KalmanStep.update`). :func:`run_kalman` does everything else, the same
way for every filter:

1. the initial state ``[q̂, ω̂ | b | z]`` and block-diagonal covariance;
2. per epoch k > 0 with Δt ≠ 0: the error-state ``(Φ, Q_d, φ_b)`` of the layout, the step's
   time update, then the controlled model's random-walk ACS noise ``P_θθ += σ_ζ² I``
   (Bernard eq. 7.8–7.11) and symmetrisation;
3. attitude-known mode (§10.7): q̂, ω̂ set to the truth of the epoch;
4. screening: a NaN magnitude is flagged and counted; an unlit / below-horizon epoch is
   skipped by the innovation gate (:mod:`lightcurve.filters.gating`); otherwise the step's
   measurement update (which applies the gate to its innovation);
5. the per-epoch records (estimate, covariance, reflection-state histories) and the
   :class:`~lightcurve.filters.result.Estimate`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ._common import (FilterProblem, Recorder, StateLayout, attach_histories, initial_state_ext,
                      layout_transition, reflection_histories, store_epoch, truth_state)
from .gating import InnovationGate
from .result import FLAG_NAN, Estimate

__all__ = ["KalmanState", "KalmanStep", "StepBase", "run_kalman"]


@dataclass
class KalmanState:
    """The estimate carried by the loop: ``q`` (4,) inertial→body quaternion, ``w`` (3,) body
    rate rad/s, ``b`` (nb,) site biases mag, ``z`` (nz,) Model 3 states, ``P`` (nx, nx)
    covariance of the error state ``[δθ, δω | δb | δz]`` laid out by ``layout``."""

    layout: StateLayout
    q: np.ndarray
    w: np.ndarray
    b: np.ndarray
    z: np.ndarray
    P: np.ndarray


class KalmanStep(Protocol):
    """What a Kalman filter contributes to :func:`run_kalman`."""

    method: str
    """Name recorded in the Estimate ("mekf", "ukf")."""
    gate_auto: str
    """What the gate's mode "auto" means for this filter ("reject" or "inflate")."""

    def predict(self, x: KalmanState, k: int, dt: float, Phi, Qd, phib, rec) -> None:
        """Time update of ``x`` over ``dt`` s to epoch k, in place; ``x.P`` before the ACS
        random-walk term and symmetrisation (added by the loop). ``Phi``, ``Qd`` the linear
        error-state transition of the layout, ``phib`` the bias block's diagonal (or None)."""
        ...

    def update(self, x: KalmanState, k: int, y: float, rec) -> None:
        """Measurement update with the finite magnitude ``y`` of epoch k, in place (the prior
        kept, and the epoch flagged in ``rec``, when the update is refused or gated out)."""
        ...


class StepBase:
    """What every step holds: the problem, its extra states (``bias``, ``facets``) and the ACS
    noise covariance ζ of its dynamics (3×3, rad²)."""

    def __init__(self, problem: FilterProblem, bias=None, facets=None):
        self.p = problem
        self.bias = bias
        self.facets = facets
        self.zc = problem.dynamics.zeta_cov


def run_kalman(problem: FilterProblem, step: KalmanStep, bias=None, facets=None) -> Estimate:
    """Run ``step`` over every epoch of ``problem`` (module docstring) → :class:`Estimate`."""
    t0 = time.perf_counter()
    p = problem
    m = p.model
    dyn = p.dynamics
    rec = Recorder(p, step.method)
    rec.gate = InnovationGate(p, auto=step.gate_auto)
    L, q, w, b, z, P = initial_state_ext(p, bias, facets)
    x = KalmanState(L, q, w, b, z, P)
    na = L.na
    hists = reflection_histories(p.n, L.nb, L.nz)
    zc = dyn.zeta_cov
    for k in range(p.n):
        if k > 0:
            dt = float(m.t[k] - m.t[k - 1])
            if dt != 0.0:
                Phi, Qd, phib = layout_transition(dyn, L, bias, facets, x.w, dt)
                step.predict(x, k, dt, Phi, Qd, phib, rec)
                if na and p.random_walk_zeta():
                    x.P[:3, :3] += zc
                x.P = 0.5 * (x.P + x.P.T)
        if not na:
            x.q, x.w = truth_state(p, k)
        y = m.y[k]
        if not np.isfinite(y):
            rec.flags[k] |= FLAG_NAN
            rec.skipped_nan += 1
        elif not rec.gate.skip_epoch(k, rec):   # unlit / below the horizon: flagged, counted
            step.update(x, k, y, rec)
        store_epoch(rec, k, L, x.q, x.w, x.b, x.z, x.P, hists)
    est = rec.gate.finish(rec.finish(time.perf_counter() - t0))
    return attach_histories(est, L, bias, facets, hists)
