"""Interfaces between filters and models (``typing.Protocol``; structural, nothing to inherit).

A filter of :mod:`lightcurve.filters` or :mod:`lightcurve.css` is written against these
protocols, so the lightcurve magnitude model and the CSS voltage model are interchangeable
measurement models, and the controlled / uncontrolled truth models interchangeable dynamics.

Conventions
-----------
* ``states`` is an (N, n) float array: one row per particle or sigma point (N = 1 for an EKF).
  Its layout is the model's business (for attitude: quaternion scalar first, inertial→body,
  then ω in rad/s in body axes, then extra states; see DESIGN.md "State layout").
* ``k`` is the epoch index into the model's time grid (seconds since the scenario epoch);
  models hold their own times and geometry per epoch.
* Jacobians are with respect to the filter's *error-state* parameterisation when the state is
  not a vector space (attitude: the 3-component GRP/small-angle error, so an (n−1)-column
  Jacobian for a quaternion state); the model documents which.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = [
    "MeasurementModel",
    "DifferentiableMeasurementModel",
    "DynamicsModel",
    "LinearizableDynamicsModel",
]


@runtime_checkable
class MeasurementModel(Protocol):
    """Maps states to predicted measurements at epoch ``k``.

    Attributes
    ----------
    dim_y : int
        Measurement dimension m.
    """

    dim_y: int

    def predict(self, states: np.ndarray, k: int) -> np.ndarray:
        """Predicted measurements ``h(states, t_k)``: (N, n) → (N, m), vectorised over rows."""
        ...

    def noise_cov(self, k: int) -> np.ndarray:
        """Measurement-noise covariance R (m, m) at epoch k, in measurement units squared."""
        ...


@runtime_checkable
class DifferentiableMeasurementModel(MeasurementModel, Protocol):
    """A measurement model that also gives ``H = ∂h/∂x`` (analytic or complex-step)."""

    def jacobian(self, state: np.ndarray, k: int) -> np.ndarray:
        """Jacobian (m, n_err) of the measurement at one state (n,) and epoch k."""
        ...


@runtime_checkable
class DynamicsModel(Protocol):
    """Propagates states from epoch ``k`` to epoch ``k + 1``.

    Attributes
    ----------
    dim_x : int
        State dimension n (rows of ``states``).
    """

    dim_x: int

    def propagate(self, states: np.ndarray, k: int,
                  rng: np.random.Generator | None = None) -> np.ndarray:
        """States at ``t_{k+1}`` from states (N, n) at ``t_k``.

        With ``rng=None`` the deterministic (mean) dynamics; with a Generator one process-noise
        realisation per row is added (bootstrap particle filter, truth simulation).
        """
        ...

    def process_noise_cov(self, k: int) -> np.ndarray:
        """Discrete process-noise covariance Q_k (n_err, n_err) of the step k → k+1."""
        ...


@runtime_checkable
class LinearizableDynamicsModel(DynamicsModel, Protocol):
    """Dynamics that also give the state-transition matrix ``F = ∂f/∂x`` of one step."""

    def jacobian(self, state: np.ndarray, k: int) -> np.ndarray:
        """State-transition matrix Φ(t_{k+1}, t_k) (n_err, n_err) about one state (n,)."""
        ...
