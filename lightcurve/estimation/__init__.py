"""Generic estimation core shared by the lightcurve attitude filters and the CSS filters.

Modules (one concept each):

* :mod:`~lightcurve.estimation.kalman` — prediction, Joseph-form / consider (Schmidt)
  updates, symmetrisation, Cholesky with a failure flag (the arithmetic: :mod:`lightcurve.core`);
* :mod:`~lightcurve.estimation.sigma_points` — scaled unscented weights and sigma points,
  unscented transform and update, augmented-state helpers (USQUE style);
* :mod:`~lightcurve.estimation.particles` — log weights, log-sum-exp, effective sample size,
  systematic / stratified / multinomial resampling (numba), roughening, weighted moments;
* :mod:`~lightcurve.estimation.consistency` — NEES, NIS, NMEE, chi-square intervals,
  sliding-window NIS divergence detection;
* :mod:`~lightcurve.estimation.protocols` — the state-space model the filters drive
  (attitude dynamics, measurement model);
* :mod:`~lightcurve.estimation.jacobians` — complex-step and central-difference Jacobians;
* :mod:`~lightcurve.estimation.rng` — seeds and Generators (reproducibility).
"""

from .consistency import (
    ConsistencyResult,
    NISDivergenceDetector,
    averaged_nees,
    averaged_nis,
    chi2_consistency,
    chi2_interval,
    correlated_average_upper,
    nees,
    nis,
    nmee,
    nmee_interval,
    normalized_squared,
    windowed_average,
)
from .jacobians import central_difference_jacobian, complex_step_jacobian
from .kalman import (
    UpdateInfo,
    consider_update,
    joseph_update,
    kf_predict,
    safe_cholesky,
    symmetrize,
)
from .particles import (
    RESAMPLING_METHODS,
    effective_sample_size,
    effective_sample_size_log,
    gaussian_log_likelihood,
    logsumexp,
    multinomial_resample,
    normalize_log_weights,
    resample,
    roughen,
    roughening_sigma,
    stratified_resample,
    systematic_resample,
    update_log_weights,
    weighted_mean_cov,
)
from .protocols import AttitudeDynamics, MeasurementModel
from .rng import as_generator
from .sigma_points import (
    UnscentedWeights,
    UTResult,
    augment,
    sigma_offsets,
    sigma_points,
    split_augmented,
    unscented_covariance,
    unscented_cross_covariance,
    unscented_mean,
    unscented_transform,
    unscented_update,
    unscented_weights,
)

__all__ = [
    # kalman
    "UpdateInfo", "symmetrize", "safe_cholesky", "kf_predict", "joseph_update",
    "consider_update",
    # sigma points
    "UnscentedWeights", "unscented_weights", "sigma_offsets", "sigma_points",
    "unscented_mean", "unscented_covariance", "unscented_cross_covariance", "UTResult",
    "unscented_transform", "unscented_update", "augment", "split_augmented",
    # particles
    "logsumexp", "normalize_log_weights", "effective_sample_size",
    "effective_sample_size_log", "gaussian_log_likelihood", "update_log_weights",
    "systematic_resample", "stratified_resample", "multinomial_resample", "resample",
    "RESAMPLING_METHODS", "roughening_sigma", "roughen", "weighted_mean_cov",
    # consistency
    "normalized_squared", "nees", "nis", "chi2_interval", "averaged_nees", "averaged_nis",
    "nmee", "nmee_interval", "ConsistencyResult", "chi2_consistency", "windowed_average",
    "NISDivergenceDetector",
    # interfaces and helpers
    "AttitudeDynamics", "MeasurementModel", "complex_step_jacobian",
    "central_difference_jacobian", "as_generator",
]
