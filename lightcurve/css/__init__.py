"""Coarse sun sensors (O'Keefe 2015, ch. 2-3): sensor, albedo and gyro models, single-point
and sequential sun-direction estimators, MRP sun-pointing control, truth simulation and
Monte Carlo studies.

Modules: :mod:`.sensors` (eq. 2.19, 2.21), :mod:`.configurations` (tables 2.1, 2.2, TOML),
:mod:`.albedo` (eq. 2.15-2.18, CERES/TOMS maps, built-in zonal model), :mod:`.gyro`
(eq. 2.23-2.50, table 2.3), :mod:`.allan` (eq. 2.52), :mod:`.single_point` (eq. 3.3,
3.9-3.12, figs. 3.1-3.2), :mod:`.sunline_ekf` (eq. 3.27-3.31, §3.2.2, eq. 3.67),
:mod:`.control` (eq. 3.64), :mod:`.truth` (§2.4), :mod:`.study`, :mod:`.recording`.
O'Keefe's own set-up: :mod:`.okeefe2015` (every value with its section), :mod:`.experiments`
(scenarios), :mod:`.sunline_thesis` (the thesis-variant EKF/ECKF of §3.2).

Chapter 4-5 and DiGregorio: :mod:`.attitude_ekf` (MRP EKF with gyro bias, eq. 4.5-4.11,
star-tracker update), :mod:`.calibration` (full and reduced calibration ECKF, §4.2-4.4),
:mod:`.sun_models` (almanac vs DE421, eq. 4.39, table 4.5), :mod:`.fault` (averaged per-sensor
NIS fault detection, §5.1), :mod:`.vmm` (voltage vs sun-vector measurement model MEKF).
"""

from .albedo import AlbedoMap, builtin_albedo_map, load_albedo_map, zonal_albedo
from .configurations import cube, dual_pyramid, load_configuration
from .control import ControlParams
from .gyro import GYRO_GRADES, GyroSpec, simulate_gyro
from .sensors import CSSArray
from .single_point import error_map, estimate
from .sunline_ekf import FilterParams, run_filter
from .truth import CSSScenario, Dispersions, Spacecraft, simulate_css, simulate_css_cases
from .experiments import thesis_scenario
from .calibration import CalibrationParams, run_calibration, simulate_calibration_case
from .fault import AveragedNISDetector, inject_fault, run_fault_case

__all__ = ["AlbedoMap", "builtin_albedo_map", "load_albedo_map", "zonal_albedo", "cube",
           "dual_pyramid", "load_configuration", "ControlParams", "GYRO_GRADES", "GyroSpec",
           "simulate_gyro", "CSSArray", "error_map", "estimate", "FilterParams", "run_filter",
           "Dispersions", "CSSScenario", "Spacecraft", "simulate_css", "simulate_css_cases",
           "thesis_scenario", "CalibrationParams",
           "run_calibration", "simulate_calibration_case", "AveragedNISDetector", "inject_fault",
           "run_fault_case"]
