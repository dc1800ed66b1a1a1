"""Attitude dynamics: kinematics, Euler's equations, environmental torques, truth models,
linearised error dynamics and integrators (Bernard 2021 ch. 4 and 7, appendix A).

Conventions: quaternion scalar first, inertial→body passive (``v_b = A(q) v_I``); ``ω`` the body
angular velocity in body axes (rad/s); SI units; ECI = GCRS. Error state ``[δθ, δω]`` with
``q_true = exp(δθ) ⊗ q̂``.

Modules: :mod:`.kinematics`, :mod:`.rigid_body`, :mod:`.torques`, :mod:`.atmosphere`,
:mod:`.truth`, :mod:`.jacobians`, :mod:`.integrators`.
"""

from .atmosphere import EXPONENTIAL_TABLE, R_EARTH_M, altitude_m, density_kg_m3
from .integrators import integrate_truth, rk4_propagate, rk4_propagate_nb
from .jacobians import (
    acs_noise_covariance,
    controlled_F,
    drag_torque_jacobian,
    eta_noise_covariance,
    gravity_gradient_jacobian,
    nonlinear_error_rate,
    srp_torque_jacobian,
    transition_matrix,
    uncontrolled_F,
    uncontrolled_F_models,
)
from .kinematics import propagate_constant_rate, quat_derivative
from .rigid_body import (
    angular_momentum_inertial,
    check_inertia,
    euler_omega_dot,
    rotational_energy,
    state_derivative,
)
from .torques import (
    AU_M,
    MU_EARTH,
    OMEGA_EARTH,
    P_SUN_1AU,
    ConstantTorque,
    DragTorque,
    GravityGradientTorque,
    SRPTorque,
    TorqueSum,
    as_time_function,
    drag_torque,
    gravity_gradient_torque,
    gravity_gradient_torque_nb,
    srp_torque,
)
from .truth import ControlledTruth, UncontrolledTruth, srp_coefficients_from_materials

__all__ = [
    "EXPONENTIAL_TABLE", "R_EARTH_M", "altitude_m", "density_kg_m3",
    "integrate_truth", "rk4_propagate", "rk4_propagate_nb",
    "acs_noise_covariance", "controlled_F", "drag_torque_jacobian", "eta_noise_covariance",
    "gravity_gradient_jacobian", "nonlinear_error_rate", "srp_torque_jacobian",
    "transition_matrix", "uncontrolled_F", "uncontrolled_F_models",
    "propagate_constant_rate", "quat_derivative",
    "angular_momentum_inertial", "check_inertia", "euler_omega_dot", "rotational_energy",
    "state_derivative",
    "AU_M", "MU_EARTH", "OMEGA_EARTH", "P_SUN_1AU", "ConstantTorque", "DragTorque",
    "GravityGradientTorque", "SRPTorque", "TorqueSum", "as_time_function", "drag_torque",
    "gravity_gradient_torque", "gravity_gradient_torque_nb", "srp_torque",
    "ControlledTruth", "UncontrolledTruth", "srp_coefficients_from_materials",
]
