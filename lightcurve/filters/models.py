"""Dynamics and measurement models of the lightcurve attitude filters.

State and error state (DESIGN.md "Estimation core")
----------------------------------------------------
The global state is ``x = [q (4), ω (3)]``: ``q`` the inertial(ECI = GCRS)→body quaternion,
scalar first, passive (``v_b = A(q) v_I``); ``ω`` the body rate in body axes, rad/s. The
filters estimate the 6-component error ``δx = [δθ (3), δω (3)]`` with ``q_true = δq(δθ) ⊗ q̂``
(``δθ`` a body-frame rotation vector or, for the UKF/PF, a GRP with a = 1, f = 4, both ≈ the
rotation angle for small errors) and ``δω = ω_true − ω̂``. To first order (Bernard eq. 7.24,
7.37; :mod:`lightcurve.dynamics.jacobians`) ``δθ̇ = −[ω̂×] δθ + δω``.

Dynamics models
---------------
* :class:`ControlledDynamics` — constant body rate (exact step ``q ← exp(ω Δt) ⊗ q``) and the
  attitude-control error ζ ~ N(0, σ_ζ² I₃) (rad, body axes) acting at every new measurement
  time (Bernard eq. 7.8–7.11). Two readings of ζ, matching
  :class:`lightcurve.dynamics.truth.ControlledTruth`'s ``mode``:

  - ``"random_walk"`` (the truth's default): ``q_k = exp(ζ_k) ⊗ exp(ω Δt) ⊗ q_{k−1}``; ζ is a
    real change of the attitude, so the filters add ``σ_ζ² I`` to the attitude block of the
    predicted covariance (PF: every particle gets its own ζ draw);
  - ``"jitter"``: ζ perturbs the nominal profile without accumulating; then ζ only enters the
    measurement, and the MEKF maps it into the measurement covariance
    ``R_eff = R + H_θ σ_ζ² H_θᵀ`` (Bernard eq. 7.27); the UKF augments its sigma points with ζ.

  Optional small pseudo-noise (white rate noise of PSD ``pseudo_noise`` (rad/s)²/s, i.e. a rate
  random walk) keeps the filter open.
* :class:`UncontrolledDynamics` — torque-free Euler's equations (RK4, ``substep_s``) with
  white angular-acceleration noise η (PSD σ_η², rad²/s³); Φ and the discrete covariance by
  Van Loan's method over the RK4 sub-steps (equal to
  :func:`lightcurve.dynamics.jacobians.eta_noise_covariance` "continuous" when ω = 0).

Measurement model
-----------------
:class:`MagnitudeModel` — the apparent magnitude of the shape for a batch of attitudes at one
epoch (DESIGN.md equation, Bernard eq. 5.2–5.6 consistent form), vectorised over particles or
sigma points with a numba kernel (numpy photometry for BRDFs without a kernel), noise σ from
the lightcurve's ``mag_sigma``, the partial ``∂m/∂δθ`` analytic
(:func:`lightcurve.photometry.magnitude_partials`) or by central differences. With Model 3
facet-parameter states the same measurement is evaluated with per-state facet arrays and
partials ``∂m/∂z`` by :class:`lightcurve.filters.facet_states.FacetParameterStates`
(``magnitudes``, ``partials``), using this model's geometry and offsets.
"""

from __future__ import annotations

import numpy as np

from ..core import dynamics as CD
from ..core.constants import AU_M, SUN_MAG_V
from ..core.photometry import mag_kernel_nb
from ..core.rotations import perturb_rotvec_nb
from ..dynamics.rigid_body import check_inertia
from ..errors import InputError
from ..photometry.magnitude import apparent_magnitude
from ..photometry.partials import magnitude_partials

_EYE3 = np.eye(3)  # inertia argument of the error-F kernel; the controlled model ignores it


def _finite_rate(omega):
    """``omega`` as a contiguous (3,) float array; ValueError for NaN/inf (as the NumPy path)."""
    w = np.ascontiguousarray(omega, dtype=float).reshape(3)
    if not np.isfinite(w).all():
        raise ValueError("omega: contains NaN or infinite values")
    return w

__all__ = ["MagnitudeModel", "ControlledDynamics", "UncontrolledDynamics"]


# --------------------------------------------------------------------------------------------
# Dynamics
# --------------------------------------------------------------------------------------------

class ControlledDynamics:
    """Constant-rate (controlled) attitude dynamics with ACS noise ζ (module docstring).

    Parameters
    ----------
    acs_sigma_rad : float ≥ 0
        1σ of each component of ζ, rad.
    acs_mode : {"random_walk", "jitter"}
        How ζ acts (module docstring).
    pseudo_noise : float ≥ 0
        PSD of an optional white rate noise, (rad/s)²/s (0 = none).
    """

    kind = "controlled"

    def __init__(self, acs_sigma_rad=0.0, acs_mode="random_walk", pseudo_noise=0.0):
        self.acs_sigma = float(acs_sigma_rad)
        if not (self.acs_sigma >= 0.0 and np.isfinite(self.acs_sigma)):
            raise ValueError(f"acs_sigma_rad must be finite and >= 0, got {acs_sigma_rad}")
        if acs_mode not in ("random_walk", "jitter"):
            raise ValueError(f"acs_mode must be 'random_walk' or 'jitter', got {acs_mode!r}")
        self.acs_mode = acs_mode
        self.pseudo_noise = float(pseudo_noise)
        if not (self.pseudo_noise >= 0.0 and np.isfinite(self.pseudo_noise)):
            raise ValueError(f"pseudo_noise must be finite and >= 0, got {pseudo_noise}")
        self.J = None
        self.J_inv = None

    def propagate(self, q, w, dt):
        """Propagate attitudes q (S,4) and rates w (S,3) by dt s (new arrays; exact step)."""
        Q = np.ascontiguousarray(q, dtype=float).copy()
        W = np.ascontiguousarray(w, dtype=float).copy()
        if dt != 0.0:
            CD.const_rate_batch_nb(Q, W, float(dt))
        return Q, W

    def transition(self, omega, dt):
        """``(Φ, Q_d)`` of the error state over dt s about the rate ``omega`` (without ζ).

        Without pseudo-noise Φ is the closed form of ``exp(F Δt)`` for eq. 7.24:
        ``Φθθ = exp(−[ω×]Δt)``, ``Φθω = I Δt − (1 − cos φ)/|ω|² [ω×]
        + (Δt − sin φ/|ω|)/|ω|² [ω×]²`` (φ = |ω| Δt), ``Φωω = I``; otherwise Van Loan.
        Kernels :func:`lightcurve.core.dynamics.controlled_transition_nb`,
        :func:`~lightcurve.core.dynamics.error_F_nb`, :func:`~lightcurve.core.dynamics.van_loan_nb`.
        """
        dt = float(dt)
        w = _finite_rate(omega)
        if self.pseudo_noise == 0.0:
            return CD.controlled_transition_nb(w, dt), np.zeros((6, 6))
        Qc = np.zeros((6, 6))
        Qc[3:, 3:] = self.pseudo_noise * np.eye(3)
        F = np.empty((6, 6))
        CD.error_F_nb(w, _EYE3, _EYE3, False, F)
        Phi, Qd = np.empty((6, 6)), np.empty((6, 6))
        CD.van_loan_nb(F, Qc, dt, Phi, Qd)
        return Phi, Qd

    @property
    def zeta_cov(self):
        """3×3 covariance of ζ, rad²."""
        return self.acs_sigma ** 2 * np.eye(3)


class UncontrolledDynamics:
    """Torque-free rigid-body dynamics with white angular-acceleration noise η.

    Parameters
    ----------
    J : (3,3) inertia about the centre of mass, body axes, kg m².
    eta_psd : float ≥ 0
        PSD σ_η² of η, rad²/s³ (the filter's process-noise level).
    substep_s : float > 0
        Largest RK4 sub-step, s.
    pseudo_noise : float ≥ 0
        Extra white rate-noise PSD added to η's, (rad/s)²/s.
    """

    kind = "uncontrolled"

    def __init__(self, J, eta_psd=0.0, substep_s=0.5, pseudo_noise=0.0):
        self.J = check_inertia(J)
        self.J_inv = np.linalg.inv(self.J)
        self.eta_psd = float(eta_psd) + float(pseudo_noise)
        if not (self.eta_psd >= 0.0 and np.isfinite(self.eta_psd)):
            raise ValueError(f"eta_psd must be finite and >= 0, got {eta_psd}")
        self.substep = float(substep_s)
        if not self.substep > 0.0:
            raise ValueError(f"substep_s must be > 0, got {substep_s}")
        self.acs_sigma = 0.0
        self.acs_mode = "random_walk"

    def nsub(self, dt):
        """Number of RK4 sub-steps for a step of dt s."""
        return max(1, int(np.ceil(abs(dt) / self.substep)))

    def propagate(self, q, w, dt):
        """Propagate q (S,4), w (S,3) by dt s with torque-free RK4 (new arrays)."""
        Q = np.ascontiguousarray(q, dtype=float).copy()
        W = np.ascontiguousarray(w, dtype=float).copy()
        if dt != 0.0:
            n = self.nsub(dt)
            CD.rk4_propagate_nb(Q, W, self.J, self.J_inv, float(dt) / n, n, None)
        return Q, W

    def transition(self, omega, dt):
        """``(Φ, Q_d)`` of the error state over dt s starting from the rate ``omega``.

        Φ is the product of ``exp(F(ω_j) h)`` over the RK4 sub-steps with ``ω_j`` the rate at
        each sub-step's midpoint (Euler's equations, torque free), so it follows the rate's
        evolution; ``Q_d`` accumulates the Van Loan discretisation of the white η (PSD on the
        rate block) over the same sub-steps (kernel
        :func:`lightcurve.core.dynamics.uncontrolled_transition_nb`).
        """
        dt = float(dt)
        w = _finite_rate(omega)
        return CD.uncontrolled_transition_nb(w, self.J, self.J_inv, self.eta_psd, dt,
                                             self.nsub(dt))

    @property
    def zeta_cov(self):
        """No ACS noise in the uncontrolled model (3×3 zeros)."""
        return np.zeros((3, 3))


# --------------------------------------------------------------------------------------------
# Measurement
# --------------------------------------------------------------------------------------------

class MagnitudeModel:
    """Apparent-magnitude measurement model of a lightcurve (module docstring).

    Parameters
    ----------
    shape : lightcurve.photometry.Shape
    curve : lightcurve.io.lightcurve_h5.Lightcurve
        Supplies times ``t`` (s), magnitudes ``mag``, 1σ ``mag_sigma`` and the geometry
        (object→Sun and object→observer unit vectors in ECI, ranges in m, lit fraction).
    sun_mag : float, optional
        Sun's apparent magnitude at 1 au; default ``curve.attrs["sun_mag"]`` or −26.74 (V).

    Attributes
    ----------
    dim_y : int = 1
    t, y, sigma : (N,) arrays (s, mag, mag)
    site : (N,) int site index of every epoch (per-site reflection biases)
    """

    dim_y = 1

    def __init__(self, shape, curve, sun_mag=None):
        self.shape = shape
        self.t = np.asarray(curve.t, float)
        self.y = np.asarray(curve.mag, float)
        self.sigma = np.asarray(curve.mag_sigma, float)
        N = self.t.shape[0]
        site = getattr(curve, "site", None)
        self.site = np.zeros(N, np.int64) if site is None else np.asarray(site, np.int64).reshape(-1)
        if self.y.shape != (N,) or self.sigma.shape != (N,):
            raise InputError("mag and mag_sigma must have one entry per time", field="mag",
                             value=(self.y.shape, self.sigma.shape), allowed=f"({N},)")
        if sun_mag is None:
            sun_mag = curve.attrs.get("sun_mag", SUN_MAG_V) if curve.attrs else SUN_MAG_V
        self.sun_mag = float(sun_mag)
        self.s_eci = np.ascontiguousarray(curve.obj_to_sun_unit)
        self.o_eci = np.ascontiguousarray(curve.obj_to_obs_unit)
        self.range_obs = np.asarray(curve.range_obs_m, float)
        self.range_sun = np.asarray(curve.range_sun_m, float)
        el = getattr(curve, "elevation_rad", None)   # rad or None; screened in filters.gating
        self.elevation_rad = None if el is None else np.asarray(el, float)
        self.offset = (self.sun_mag + 5.0 * np.log10(self.range_obs)
                       + 5.0 * np.log10(self.range_sun / AU_M))
        self.lit_offset = np.zeros(N)
        lit = getattr(curve, "lit_fraction", None)
        ignore = bool(int(curve.attrs.get("ignore_eclipse", 0))) if curve.attrs else False
        if lit is not None and not ignore:
            lit = np.asarray(lit, float)
            with np.errstate(divide="ignore"):
                self.lit_offset = np.where(lit > 0, -2.5 * np.log10(np.where(lit > 0, lit, 1.0)),
                                           np.inf)
        self.offset = self.offset + self.lit_offset
        self._kernel = bool(shape.all_kernel)
        n, a, ids, p = shape.kernel_arrays()
        self._karrs = (np.ascontiguousarray(n), np.ascontiguousarray(a),
                       np.ascontiguousarray(ids), np.ascontiguousarray(p))

    def __len__(self):
        return self.t.shape[0]

    @property
    def kernel_arrays(self):
        """The shape packed for the kernels: ``(normals (F,3), areas (F,), ids (F,),
        params (F,7))``, C-contiguous (:mod:`lightcurve.core.photometry`)."""
        return self._karrs

    @property
    def kernel_ok(self) -> bool:
        """True when every facet's BRDF has a numba kernel (fast particle path)."""
        return self._kernel

    def predict_q(self, q, k):
        """Predicted magnitudes (S,) of attitudes q (S,4) (inertial→body) at epoch k; +inf where
        no light reaches the observer."""
        Q = np.ascontiguousarray(np.asarray(q, float).reshape(-1, 4))
        if self._kernel:
            n, a, ids, p = self._karrs
            return mag_kernel_nb(Q, self.s_eci[k], self.o_eci[k], n, a, ids, p,
                                   float(self.offset[k]))
        with np.errstate(divide="ignore"):
            m = apparent_magnitude(self.shape, Q[None, :, :], self.s_eci[k:k + 1],
                                   self.o_eci[k:k + 1], self.range_obs[k:k + 1],
                                   self.range_sun[k:k + 1], sun_mag=self.sun_mag)[0]
        return m + self.lit_offset[k]

    def predict(self, states, k):
        """Protocol form: states (S,7) = [q (4), ω (3)] → (S,1) magnitudes."""
        s = np.asarray(states, float).reshape(-1, 7)
        return self.predict_q(s[:, :4], k)[:, None]

    def noise_cov(self, k):
        """R (1,1) = mag_sigma[k]², mag²."""
        return np.array([[self.sigma[k] ** 2]])

    def jacobian_theta(self, q, k, method="analytic", h=1e-6):
        """``∂m/∂δθ`` (3,) at the attitude q (4,), mag/rad, for ``q = δq(δθ) ⊗ q̂``.

        ``method="analytic"`` uses :func:`lightcurve.photometry.magnitude_partials`;
        ``"numeric"`` central differences with step ``h`` rad (6 evaluations).
        """
        q = np.asarray(q, float).reshape(4)
        if method == "analytic":
            with np.errstate(divide="ignore", invalid="ignore"):
                mp = magnitude_partials(self.shape, q[None, :], self.s_eci[k:k + 1],
                                        self.o_eci[k:k + 1], self.range_obs[k:k + 1],
                                        self.range_sun[k:k + 1], sun_mag=self.sun_mag)
            return np.asarray(mp.dm_dtheta, float).reshape(3)
        if method != "numeric":
            raise ValueError(f"jacobian method must be 'analytic' or 'numeric', got {method!r}")
        d = np.concatenate([h * np.eye(3), -h * np.eye(3)])
        Qp = perturb_rotvec_nb(np.ascontiguousarray(np.tile(q, (6, 1))), d)
        m = self.predict_q(Qp, k)
        return (m[:3] - m[3:]) / (2.0 * h)

    def jacobian(self, state, k):
        """Protocol form: (1,6) Jacobian of m w.r.t. [δθ, δω] at state (7,)."""
        H = np.zeros((1, 6))
        H[0, :3] = self.jacobian_theta(np.asarray(state, float)[:4], k)
        return H
