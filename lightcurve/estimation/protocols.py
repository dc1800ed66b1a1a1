"""The state-space model the attitude filters drive (``typing.Protocol``: structural, nothing to
inherit).

A filter problem is *dynamics + measurement model + extra states* (DESIGN.md "Estimation core";
in the spirit of ``particles``' state-space models): the Kalman filters
(:func:`lightcurve.filters.driver.run_kalman` with the MEKF or UKF step) and the particle filter
only call the methods below, so any measurement model — the apparent magnitude
(:class:`lightcurve.filters.models.MagnitudeModel`), a coarse-sun-sensor voltage or sun-vector
model — and either dynamics model plug in.

State and error state
---------------------
The global state is ``[q (4), ω (3)]``: ``q`` the inertial→body quaternion (scalar first,
passive), ``ω`` the body rate (rad/s, body axes). Filters estimate the error
``[δθ (3), δω (3)]`` with ``q_true = δq(δθ) ⊗ q̂`` and ``δω = ω_true − ω̂``; extra states
(reflection biases, facet parameters, gyro bias, CSS calibration) append to the error state
with their own linear transition (:class:`lightcurve.filters._common.StateLayout`).
``k`` is the epoch index into the measurement model's time grid ``t`` (s).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["AttitudeDynamics", "MeasurementModel"]


@runtime_checkable
class AttitudeDynamics(Protocol):
    """Attitude dynamics: the nonlinear propagation and the linear error-state transition.

    Implemented by :class:`lightcurve.filters.models.ControlledDynamics` (constant rate + ACS
    noise ζ, Bernard eq. 7.8–7.11, 7.24) and :class:`~lightcurve.filters.models.
    UncontrolledDynamics` (Euler's equations + η, eq. 4.12–4.13, 7.37).

    Attributes
    ----------
    kind : str — "controlled" or "uncontrolled".
    acs_sigma : float — 1σ of the ACS attitude noise ζ, rad (0 without).
    acs_mode : str — "random_walk" (ζ moves the attitude) or "jitter" (ζ only perturbs the
        measurement).
    """

    kind: str
    acs_sigma: float
    acs_mode: str

    def propagate(self, q: np.ndarray, w: np.ndarray, dt: float):
        """``(Q, W)``: attitudes (S,4) and rates (S,3) advanced by ``dt`` s (new arrays),
        vectorised over particles or sigma points."""
        ...

    def transition(self, omega: np.ndarray, dt: float):
        """``(Φ, Q_d)`` (6,6) of the error state ``[δθ, δω]`` over ``dt`` s about ``omega``."""
        ...

    @property
    def zeta_cov(self) -> np.ndarray:
        """3×3 covariance of ζ, rad²."""
        ...


@runtime_checkable
class MeasurementModel(Protocol):
    """A measurement of the attitude at each epoch of a time grid.

    Attributes
    ----------
    dim_y : int — measurement dimension m (1 for a magnitude; the number of sensors for CSS
        voltages; 3 for a sun vector).
    t, y : (N,) / (N, m) arrays — times (s) and measurements (NaN: missing).
    """

    dim_y: int
    t: np.ndarray
    y: np.ndarray

    def __len__(self) -> int:
        """Number of epochs N."""
        ...

    def predict(self, states: np.ndarray, k: int) -> np.ndarray:
        """Predicted measurements (S, m) of global states (S, 7) = ``[q, ω]`` at epoch k,
        vectorised over rows (+inf / NaN where the model predicts nothing measurable)."""
        ...

    def jacobian(self, state: np.ndarray, k: int) -> np.ndarray:
        """``∂h/∂[δθ, δω]`` (m, 6) at one global state (7,) and epoch k."""
        ...

    def noise_cov(self, k: int) -> np.ndarray:
        """Measurement-noise covariance R (m, m) at epoch k."""
        ...
