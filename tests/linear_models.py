"""Linear-Gaussian models, a simulator and a generic (extended) Kalman filter run — test
references (not production code).

Vector-space models for the consistency tests of the generic Kalman machinery (NIS/NEES of a
correctly tuned filter): they use the package's :func:`~lightcurve.estimation.kalman.joseph_update`
and :func:`~lightcurve.estimation.kalman.kf_predict`.

Model: ``x_{k+1} = F x_k + w_k``, ``w_k ~ N(0, Q)``; ``y_k = H x_k + v_k``, ``v_k ~ N(0, R)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lightcurve.estimation.kalman import joseph_update, kf_predict
from lightcurve.estimation.rng import as_generator

__all__ = [
    "LinearGaussianDynamics",
    "LinearGaussianMeasurement",
    "simulate",
    "FilterRun",
    "run_ekf",
]


def _square(M, name):
    M = np.atleast_2d(np.asarray(M, dtype=float))
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise ValueError(f"{name} must be square, got shape {M.shape}")
    return M


class LinearGaussianDynamics:
    """Time-invariant linear dynamics ``x_{k+1} = F x_k + w``, ``w ~ N(0, Q)``."""

    def __init__(self, F, Q):
        self.F = _square(F, "F")
        self.Q = _square(Q, "Q")
        if self.Q.shape != self.F.shape:
            raise ValueError(f"Q {self.Q.shape} must match F {self.F.shape}")
        self.dim_x = self.F.shape[0]
        self._Lq = None

    def propagate(self, states, k, rng=None):
        """Rows of ``states`` (N, n) at step k → step k+1; process noise drawn when rng given."""
        X = np.atleast_2d(np.asarray(states, dtype=float))
        out = X @ self.F.T
        if rng is not None:
            if self._Lq is None:
                w, V = np.linalg.eigh(self.Q)
                self._Lq = V * np.sqrt(np.clip(w, 0.0, None))  # works for singular Q too
            z = as_generator(rng).standard_normal(out.shape)
            out = out + z @ self._Lq.T
        return out

    def process_noise_cov(self, k):
        """Q (n, n), the same at every step."""
        return self.Q

    def jacobian(self, state, k):
        """F (n, n)."""
        return self.F


class LinearGaussianMeasurement:
    """Linear measurement ``y = H x + v``, ``v ~ N(0, R)``."""

    def __init__(self, H, R):
        self.H = np.atleast_2d(np.asarray(H, dtype=float))
        self.R = _square(R, "R")
        if self.R.shape[0] != self.H.shape[0]:
            raise ValueError(f"R {self.R.shape} must match the {self.H.shape[0]} rows of H")
        self.dim_y = self.H.shape[0]

    def predict(self, states, k):
        """(N, n) → (N, m) noise-free measurements."""
        return np.atleast_2d(np.asarray(states, dtype=float)) @ self.H.T

    def noise_cov(self, k):
        """R (m, m)."""
        return self.R

    def jacobian(self, state, k):
        """H (m, n)."""
        return self.H


def simulate(dynamics, measurement, x0, n_steps, rng):
    """Simulate truth and noisy measurements.

    Parameters
    ----------
    dynamics : DynamicsModel (propagate with ``rng`` draws process noise).
    measurement : MeasurementModel (Gaussian noise with ``noise_cov(k)`` is added here).
    x0 : (n,) true initial state; n_steps : number of epochs T (k = 0…T−1).
    rng : Generator or seed.

    Returns
    -------
    x_true : (T, n); y : (T, m). ``y[k]`` measures ``x_true[k]``.
    """
    g = as_generator(rng)
    x = np.asarray(x0, dtype=float).reshape(1, -1)
    xs = np.empty((n_steps, x.shape[1]))
    ys = np.empty((n_steps, measurement.dim_y))
    for k in range(n_steps):
        if k > 0:
            x = dynamics.propagate(x, k - 1, rng=g)
        xs[k] = x[0]
        R = np.atleast_2d(measurement.noise_cov(k))
        v = np.linalg.cholesky(R) @ g.standard_normal(measurement.dim_y)
        ys[k] = measurement.predict(x, k)[0] + v
    return xs, ys


@dataclass(frozen=True)
class FilterRun:
    """Per-epoch output of :func:`run_ekf` (T epochs, n states, m measurements).

    ``x`` (T, n) and ``P`` (T, n, n) are the *posterior* estimates; ``innovation`` (T, m),
    ``S`` (T, m, m) and ``nis`` (T,) are NaN where no update happened; ``ok`` (T,) is False
    where the update was refused or skipped (NaN measurement); ``n_skipped`` counts the NaN
    measurements.
    """

    x: np.ndarray
    P: np.ndarray
    innovation: np.ndarray
    S: np.ndarray
    nis: np.ndarray
    ok: np.ndarray
    n_skipped: int


def run_ekf(dynamics, measurement, ys, x0, P0):
    """Extended Kalman filter over ``ys`` (T, m) for vector-space states (Joseph-form update).

    Step k: predict from k−1 (skipped at k = 0, where ``x0, P0`` is the prior at epoch 0), then
    update with ``ys[k]``. A measurement row with any NaN is skipped and counted; a refused
    update keeps the prediction and sets ``ok[k] = False``.
    """
    ys = np.asarray(ys, dtype=float)
    if ys.ndim == 1:
        ys = ys[:, None]
    if ys.ndim != 2 or ys.shape[1] != measurement.dim_y:
        raise ValueError(f"ys must have shape (T, {measurement.dim_y}), got {ys.shape}")
    T, m = ys.shape
    x = np.asarray(x0, dtype=float).ravel()
    P = np.asarray(P0, dtype=float)
    n = x.shape[0]
    X = np.empty((T, n))
    PP = np.empty((T, n, n))
    NU = np.full((T, m), np.nan)
    SS = np.full((T, m, m), np.nan)
    NIS = np.full(T, np.nan)
    OK = np.zeros(T, dtype=bool)
    skipped = 0
    for k in range(T):
        if k > 0:
            F = dynamics.jacobian(x, k - 1)
            x_pred = dynamics.propagate(x[None, :], k - 1)[0]
            _, P = kf_predict(x, P, F, dynamics.process_noise_cov(k - 1))
            x = x_pred
        y = ys[k]
        if np.all(np.isfinite(y)):
            h = measurement.predict(x[None, :], k)[0]
            H = measurement.jacobian(x, k)
            x, P, info = joseph_update(x, P, y, H, measurement.noise_cov(k), h=h)
            NU[k] = info.innovation
            SS[k] = info.S
            NIS[k] = info.nis
            OK[k] = info.ok
        else:
            skipped += 1
        X[k] = x
        PP[k] = P
    return FilterRun(x=X, P=PP, innovation=NU, S=SS, nis=NIS, ok=OK, n_skipped=skipped)
