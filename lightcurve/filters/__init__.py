"""Attitude filters on lightcurves: MEKF, USQUE/GRP UKF and a numba bootstrap particle filter.

Public API::

    invert(curve, MEKFConfig(...) | UKFConfig(...) | "mekf"|"ukf"|"bpf",
           problem=ProblemConfig(seed=…, sigma_theta_deg=…, …)) -> Estimate
    invert(curve, "ukf", seed=…, sigma_theta_deg=…, alpha=…, …)   # the same, keyword form
    build_problem(curve, ProblemConfig(...)) -> FilterProblem    # model + dynamics + initial estimate
    run_mekf(problem, MEKFConfig), run_ukf(problem, UKFConfig), run_bpf(problem, …),
    run_bpf_numpy(problem, …)
    Estimate (per-epoch q̂, ω̂, 1σ bounds, innovations, NEES, N_eff, flags; .write(), .summary())
    read_estimate(path) -> Estimate
    MagnitudeModel, ControlledDynamics, UncontrolledDynamics
    GateConfig, set_gate(problem, …)                  # outlier gate / unlit screening (gating)

Conventions (DESIGN.md): quaternions scalar first, inertial(ECI)→body passive; ω body rate in
body axes (rad/s); error state [δθ, δω] with q_true = δq(δθ) ⊗ q̂; degrees only in names *_deg.
"""

from ._common import FilterProblem
from .bpf import run_bpf, run_bpf_numpy
from .config import VARIANTS, MEKFConfig, ProblemConfig, UKFConfig, register_filter_config
from .gating import GateConfig, set_gate
from .invert import METHODS, build_problem, invert
from .mekf import run_mekf
from .models import ControlledDynamics, MagnitudeModel, UncontrolledDynamics
from .result import (FLAG_BELOW_HORIZON, FLAG_COLLAPSE, FLAG_GATE_RELEASED, FLAG_INFLATED,
                     FLAG_INVISIBLE, FLAG_NAN, FLAG_NIS, FLAG_OUTLIER, FLAG_REFUSED,
                     FLAG_RESAMPLED, FLAG_UNLIT, Estimate, read_estimate)
from .ukf import run_ukf

__all__ = [
    "invert", "build_problem", "METHODS", "FilterProblem", "run_mekf", "run_ukf", "run_bpf",
    "run_bpf_numpy", "Estimate", "read_estimate", "MagnitudeModel", "ControlledDynamics",
    "UncontrolledDynamics", "FLAG_NAN", "FLAG_REFUSED", "FLAG_INVISIBLE", "FLAG_COLLAPSE",
    "FLAG_RESAMPLED", "FLAG_NIS", "FLAG_OUTLIER", "FLAG_INFLATED", "FLAG_GATE_RELEASED",
    "FLAG_UNLIT", "FLAG_BELOW_HORIZON", "GateConfig", "set_gate", "ProblemConfig", "MEKFConfig",
    "UKFConfig", "VARIANTS", "register_filter_config",
]
