"""Truth attitude models: controlled (constant rate + ACS noise) and uncontrolled (torques + η).

Conventions: ``q`` scalar first, inertial→body (``v_b = A(q) v_I``); ``ω`` body rate in body
axes (rad/s); times in s since the scenario epoch; noise rotations act in body axes from the
left, ``q ← exp(ζ) ⊗ q`` with ``exp`` the rotation-vector quaternion (so ``ζ`` is exactly the
error-state ``δθ`` of :mod:`lightcurve.dynamics.jacobians`).

Controlled model (Bernard 2021 eq. 7.8–7.11): the attitude control system holds a constant body
rate ``ω``; between measurement epochs the attitude follows the exact constant-rate solution and
at every measurement time ``t_k`` the ACS error adds a random rotation ``ζ_k ~ N(0, σ_ζ² I₃)``
(rad, body axes):

    q_k = exp(ζ_k) ⊗ exp(ω Δt_k) ⊗ q_{k−1}          (mode "random_walk", the default)

so that the filter's process model (``δθ̇ = −[ω×]δθ + δω`` plus ``ζ`` with covariance ``σ_ζ² I``
per measurement) is the truth. ``mode="jitter"`` instead perturbs the nominal profile without
accumulation, ``q_k = exp(ζ_k) ⊗ exp(ω (t_k − t0)) ⊗ q0``. Optionally the rate also takes a
random walk ``ω_k = ω_{k−1} + N(0, σ_ω² I)``.

Uncontrolled model: Euler's equations ``J ω̇ = −ω × Jω + T(t, q) + J η`` with the environmental
torques and white angular-acceleration noise η, integrated with ``solve_ivp`` DOP853
(rtol = atol = 1e-12) between measurement epochs. ``noise="continuous"`` (default): η is white
noise with power spectral density ``σ_η²`` (the ``eta_sigma_rad_s2`` argument is σ_η, strictly in
rad/s^{3/2}); the deterministic dynamics are integrated over each interval and a correlated
random impulse ``(δθ, δω)`` with the exact discrete covariance of integrated white noise
``σ² [[Δt³/3, Δt²/2], [Δt²/2, Δt]] ⊗ I₃`` (body axes; the rotation of the error by ``−[ω×]``
within the interval is neglected) is applied at the end of the interval — the same covariance
the filters use (:func:`~lightcurve.dynamics.jacobians.eta_noise_covariance`, ``"continuous"``).
``noise="piecewise_constant"``: η is drawn ``N(0, σ_η² I₃)`` (rad/s², body axes) once per interval
and held constant over it inside the integration (exact for that model).

Randomness: a ``numpy.random.Generator`` or an integer seed; for a given seed the output is
reproducible bit for bit (draws are taken in time order, ζ (3) before rate noise (3)).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import rotations as rot
from ..core.dynamics import mat9, omega_dot_xyz, quat_rate_xyz


@njit(cache=True)
def _truth_rhs_nb(x, T, J, Ji, eta):
    """State derivative of ``x = [q (4), ω (3)]``: ``q̇ = ½ [0, ω] ⊗ q`` (Bernard eq. 4.12;
    scalar first, inertial→body), ``ω̇ = J⁻¹ (T − ω × Jω) + η`` (eq. 4.13; rad/s², body axes;
    T in N m, J kg m²) — the core's :func:`~lightcurve.core.dynamics.quat_rate_xyz` and
    :func:`~lightcurve.core.dynamics.omega_dot_xyz`."""
    out = np.empty(7)
    out[0], out[1], out[2], out[3] = quat_rate_xyz(x[0], x[1], x[2], x[3], x[4], x[5], x[6])
    e0, e1, e2 = omega_dot_xyz(x[4], x[5], x[6], mat9(J), mat9(Ji), (T[0], T[1], T[2]), None)
    out[4] = e0 + eta[0]
    out[5] = e1 + eta[1]
    out[6] = e2 + eta[2]
    return out



from ..geometry.eclipse import lit_fraction
from ..geometry.time import sun_position_gcrs
from . import _checks as ck
from .integrators import integrate_truth
from .rigid_body import check_inertia
from .torques import SampledEnvironment, environment_torque_nb

__all__ = ["ControlledTruth", "UncontrolledTruth", "srp_coefficients_from_materials",
           "srp_coefficients_thesis"]

_TORQUE_NAMES = ("gravity_gradient", "srp", "drag")


@njit(cache=True)
def _environment_rhs_nb(t, x, J, Ji, eta, *env):
    """:func:`_truth_rhs_nb` with the torque of the named environmental torques,
    :func:`~lightcurve.dynamics.torques.environment_torque_nb` ``(t, q/|q|, *env)``, in one
    compiled call (the truth integrators evaluate it thousands of times per run)."""
    q = x[:4] / np.sqrt(np.dot(x[:4], x[:4]))
    T = environment_torque_nb(t, q, *env)
    return _truth_rhs_nb(x, T, J, Ji, eta)


def srp_coefficients_from_materials(materials):
    """Specular and diffuse SRP coefficients ``(c_spec (F,), c_diff (F,))`` of facet materials.

    The momentum-transfer coefficients are taken from the reflectance parameters (an
    approximation: the SRP model of :func:`~lightcurve.dynamics.torques.srp_torque` splits
    reflected light into an ideal specular and an ideal Lambertian part):

    * explicit ``srp_c_spec`` / ``srp_c_diff`` parameters when a material has them;
    * Lambert (``albedo``): ``c_diff = albedo``, ``c_spec = 0``;
    * Cook–Torrance (``xi``, ``a`` = F0): ``c_diff = ξ a``, ``c_spec = (1 − ξ) a``;
    * Phong (``Kd``, ``Ks``): ``c_diff = Kd``, ``c_spec = Ks``;
    * Ashikhmin–Shirley (``Rd``, ``Rs``): ``c_diff = Rd (1 − Rs)``, ``c_spec = Rs``.

    Sums above one are scaled down to one. Any other BRDF raises ``ValueError`` (give the
    material ``srp_c_spec`` and ``srp_c_diff``).
    """
    cs, cd = [], []
    for m in materials:
        p = dict(getattr(m, "params", {}) or {})
        name = str(getattr(m, "brdf_name", "")).lower().replace("-", "_")
        if "srp_c_spec" in p or "srp_c_diff" in p:
            s_, d_ = p.get("srp_c_spec", 0.0), p.get("srp_c_diff", 0.0)
        elif "albedo" in p and name.startswith("lambert"):
            s_, d_ = 0.0, p["albedo"]
        elif {"xi", "a"} <= set(p):
            s_, d_ = (1.0 - p["xi"]) * p["a"], p["xi"] * p["a"]
        elif {"Kd", "Ks"} <= set(p):
            s_, d_ = p["Ks"], p["Kd"]
        elif {"Rd", "Rs"} <= set(p):
            s_, d_ = p["Rs"], p["Rd"] * (1.0 - p["Rs"])
        else:
            raise ValueError(f"material {getattr(m, 'name', m)!r} (BRDF {name or '?'}): no SRP "
                             "coefficient mapping (supported: Lambert, Cook-Torrance, Phong, "
                             "Ashikhmin-Shirley, or explicit srp_c_spec/srp_c_diff parameters)")
        s_, d_ = float(s_), float(d_)
        tot = s_ + d_
        if tot > 1.0:
            s_, d_ = s_ / tot, d_ / tot
        cs.append(s_)
        cd.append(d_)
    return np.array(cs), np.array(cd)


def srp_coefficients_thesis(materials):
    """Specular and diffuse SRP reflectivities ``(R_s (F,), R_d (F,))`` of Bernard eq. 4.17–4.18.

    ``R_d = ξ``, ``R_s = 1 − ξ`` for every Cook–Torrance material (the weighting ξ of the
    measurement model; nothing absorbed). A material without ``xi`` raises ``ValueError``.
    """
    cs, cd = [], []
    for m in materials:
        p = dict(getattr(m, "params", {}) or {})
        if "xi" not in p:
            raise ValueError(f"material {getattr(m, 'name', m)!r}: the thesis SRP form (Bernard "
                             "eq. 4.17-4.18) needs a Cook-Torrance weighting xi")
        cd.append(float(p["xi"]))
        cs.append(1.0 - float(p["xi"]))
    return np.array(cs), np.array(cd)


def _rng(rng):
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, (int, np.integer)):
        return np.random.default_rng(rng)
    raise ValueError(f"rng: expected a numpy.random.Generator or an integer seed, got {type(rng).__name__}")


def _times(t_s, t0):
    t = ck.times(t_s, "t_s")
    t0 = float(t[0]) if t0 is None else float(t0)
    if t[0] < t0:
        raise ValueError(f"t_s: first time {t[0]} precedes the initial epoch t0_s = {t0}")
    return t, t0


class _TruthModel:
    """What both truth models start from, checked in one place.

    Parameters
    ----------
    q0 : array (4,)
        Unit quaternion at ``t0_s`` (scalar first, inertial→body).
    omega0_rad_s : array (3,)
        Body rate at ``t0_s``, rad/s, body axes (the controlled model's commanded rate).
    rng : numpy.random.Generator or int seed
        Source of the model's noise.
    t0_s : float, optional
        Epoch of ``q0`` (default: the first simulated time).
    """

    def __init__(self, q0, omega0_rad_s, rng, t0_s):
        self.q0 = ck.single_quat(q0, "q0").copy()
        self.omega0 = ck.single_vec(omega0_rad_s, "omega0_rad_s").copy()
        self.rng = _rng(rng)
        self.t0 = t0_s


class ControlledTruth(_TruthModel):
    """Controlled truth attitude: constant body rate with ACS noise ζ at measurement times.

    Parameters
    ----------
    q0, omega0_rad_s, rng, t0_s
        Initial attitude, commanded constant body rate, noise generator and epoch (as in
        ``_TruthModel``). Noise is applied at every measurement time strictly after ``t0_s``.
    acs_sigma_rad : float
        Standard deviation of each component of the ACS rotation-vector noise ζ, rad.
        Repeated (simultaneous) measurement times share one draw and one attitude.
    mode : {"random_walk", "jitter"}
        Accumulating ACS noise (default) or jitter about the nominal constant-rate profile.
    rate_sigma_rad_s : float
        Optional per-measurement random-walk step of the rate (rad/s, each component); 0 = none.
    """

    def __init__(self, q0, omega0_rad_s, acs_sigma_rad, rng=None, *, t0_s=None, mode="random_walk",
                 rate_sigma_rad_s: float = 0.0):
        super().__init__(q0, omega0_rad_s, rng, t0_s)
        self.acs_sigma = ck.finite_scalar(acs_sigma_rad, "acs_sigma_rad", nonneg=True)
        self.rate_sigma = ck.finite_scalar(rate_sigma_rad_s, "rate_sigma_rad_s", nonneg=True)
        self.mode = ck.one_of(mode, "mode", ("random_walk", "jitter"))

    def simulate(self, t_s):
        """Attitudes and rates at the measurement times ``t_s`` (s): ``(q (N,4), ω (N,3))``."""
        t, t0 = _times(t_s, self.t0)
        N = t.size
        qs = np.empty((N, 4))
        ws = np.empty((N, 3))
        state = self.q0.copy()  # propagated attitude (nominal in "jitter" mode)
        w = self.omega0.copy()
        t_prev = t0
        for k in range(N):
            if k > 0 and t[k] == t[k - 1]:  # simultaneous measurements share one attitude
                qs[k], ws[k] = qs[k - 1], ws[k - 1]
                continue
            state = rot.quat_mult(rot.rotvec_to_quat(w * (t[k] - t_prev)), state)
            state = state / np.linalg.norm(state)
            q = state
            if t[k] > t0:
                zeta = self.rng.normal(0.0, 1.0, 3) * self.acs_sigma
                q = rot.quat_mult(rot.rotvec_to_quat(zeta), state)
                q = q / np.linalg.norm(q)
                if self.mode == "random_walk":
                    state = q
            qs[k] = q
            ws[k] = w
            if t[k] > t0 and self.rate_sigma > 0:
                w = w + self.rng.normal(0.0, 1.0, 3) * self.rate_sigma
            t_prev = t[k]
        return qs, ws


class UncontrolledTruth(_TruthModel):
    """Uncontrolled (tumbling) truth attitude: Euler's equations + torques + noise η.

    Parameters
    ----------
    q0, omega0_rad_s, rng, t0_s
        Initial attitude, initial body rate, noise generator and epoch of the initial state
        (as in ``_TruthModel``).
    J : array (3, 3)
        Inertia, kg m², body axes.
    torque_models : sequence
        Objects with ``torque(t, q, omega) -> (3,)`` N m body axes (see
        :mod:`lightcurve.dynamics.torques`) or plain callables ``(t, q, omega)``. They carry
        their own orbit geometry (position, velocity, Sun direction as functions of time).
    eta_sigma_rad_s2 : float
        Angular-acceleration noise level (see the module docstring for the two meanings).
    noise : {"continuous", "piecewise_constant"}
        Meaning of η (module docstring); default "continuous" (white noise, impulse per interval).
    rtol, atol : float
        DOP853 tolerances (default 1e-12).
    torques : sequence of {"gravity_gradient", "srp", "drag"}, optional
        Named environmental torques built from ``orbit`` (an object with
        ``positions(epoch_utc, t_s) -> (r (N,3) m, v (N,3) m/s)`` in GCRS), ``epoch_utc`` and, for
        SRP and drag, ``shape`` (``areas_m2``, ``normals_body``, ``centers_body_m``,
        ``materials``). The orbit, the Sun (:func:`lightcurve.geometry.time.sun_position_gcrs`)
        and the lit fraction (:func:`lightcurve.geometry.eclipse.lit_fraction`, conical) are
        sampled every ``geometry_step_s`` over the simulated span and interpolated (cubic
        spline for positions, linear for the lit fraction). SRP coefficients come from
        :func:`srp_coefficients_from_materials`. Added to ``torque_models``.
    geometry_step_s : float
        Sampling step of the orbit geometry for the named torques, s (default 20).
    torque_forms : {"physical", "thesis"}
        Forms of the named SRP and drag torques. ``"physical"`` (default): SRP coefficients from
        :func:`srp_coefficients_from_materials`, drag along the flow relative to the co-rotating
        atmosphere. ``"thesis"``: Bernard (2021) eq. 4.16–4.21 as written — SRP reflectivities
        ``R_d = ξ``, ``R_s = 1 − ξ`` of each Cook–Torrance facet (eq. 4.17–4.18; nothing
        absorbed), drag along the facet normal with the orbital velocity (eq. 4.21,
        ``omega_earth = 0``); gravity gradient is eq. 4.20 in both.
    """

    def __init__(self, q0, omega0_rad_s, J, torque_models=(), eta_sigma_rad_s2: float = 0.0, rng=None,
                 *, t0_s=None, noise: str = "continuous", rtol: float = 1e-12, atol: float = 1e-12,
                 torques=None, shape=None, orbit=None, epoch_utc=None, geometry_step_s: float = 20.0,
                 torque_forms: str = "physical"):
        super().__init__(q0, omega0_rad_s, rng, t0_s)
        self.torque_forms = ck.one_of(torque_forms, "torque_forms", ("physical", "thesis"))
        self.J = check_inertia(J)
        self.J_inv = np.linalg.inv(self.J)
        self.torque_fns = []
        for m in torque_models:
            if hasattr(m, "torque"):
                self.torque_fns.append(m.torque)
            elif callable(m):
                self.torque_fns.append(m)
            else:
                raise ValueError(f"torque_models: {m!r} is neither a torque model nor a callable")
        self.eta_sigma = ck.finite_scalar(eta_sigma_rad_s2, "eta_sigma_rad_s2", nonneg=True)
        self.noise = ck.one_of(noise, "noise", ("piecewise_constant", "continuous"))
        self.rtol, self.atol = float(rtol), float(atol)
        self.named_torques = tuple(torques) if torques is not None else ()
        for name in self.named_torques:
            if name not in _TORQUE_NAMES:
                raise ValueError(f"torques: unknown torque {name!r}; allowed: {', '.join(_TORQUE_NAMES)}")
        if self.named_torques and (orbit is None or epoch_utc is None):
            raise ValueError("torques: named torques need orbit= and epoch_utc=")
        if any(n in ("srp", "drag") for n in self.named_torques) and shape is None:
            raise ValueError("torques: 'srp' and 'drag' need shape= (facet areas, normals, centres)")
        self.shape, self.orbit, self.epoch_utc = shape, orbit, epoch_utc
        self.geometry_step_s = ck.finite_scalar(geometry_step_s, "geometry_step_s", positive=True)
        self._named_fns = []
        self._environment = None

    def torque(self, t, q, omega):
        """Total external torque (N m, body axes) at time ``t``."""
        T = np.zeros(3)
        for f in self.torque_fns:
            T = T + np.asarray(f(t, q, omega), dtype=float)
        for f in self._named_fns:
            T = T + np.asarray(f(t, q, omega), dtype=float)
        return T

    def build_named_torques(self, t_start: float, t_end: float):
        """Sample the geometry over ``[t_start, t_end]`` (s) as :meth:`simulate` does and return
        the named torque models (torque objects with their attitude partials) that the
        compiled sum of the truth equals."""
        self._sample_environment(t_start, t_end)
        return [] if self._environment is None else self._environment.models()

    def _sample_environment(self, t_start: float, t_end: float) -> None:
        """Sample the orbit, Sun and shadow over ``[t_start, t_end]`` (s) into the
        :class:`SampledEnvironment` of the named torques (None without named torques)."""
        if not self.named_torques:
            self._named_fns, self._environment = [], None
            return
        step = self.geometry_step_s
        n = max(4, int(np.ceil((t_end - t_start) / step)) + 1)
        tg = t_start + np.arange(n) * step
        if tg[-1] < t_end:
            tg = np.append(tg, t_end)
        r, v = self.orbit.positions(self.epoch_utc, tg)
        r, v = np.asarray(r, dtype=float), np.asarray(v, dtype=float)
        sh = self.shape
        facets = None if sh is None else {"areas_m2": sh.areas_m2, "normals_body": sh.normals_body,
                                          "centers_body_m": sh.centers_body_m}
        drag = srp = rel = lit = None
        if "drag" in self.named_torques:
            drag = dict(facets)
            if self.torque_forms == "thesis":  # eq. 4.21: along the normal, orbital velocity
                drag.update(omega_earth=0.0, form="normal")
        if "srp" in self.named_torques:
            rs = np.asarray(sun_position_gcrs(self.epoch_utc, tg), dtype=float)
            rel = rs - r
            lit = np.asarray(lit_fraction(r, rs), dtype=float)
            if self.torque_forms == "thesis":
                cs, cd = srp_coefficients_thesis(sh.materials)
            else:
                cs, cd = srp_coefficients_from_materials(sh.materials)
            srp = dict(facets, c_spec=cs, c_diff=cd)
        self._environment = SampledEnvironment(
            tg, r, v, rel, lit, gravity_gradient="gravity_gradient" in self.named_torques, J=self.J,
            drag=drag, srp=srp)
        self._named_fns = [self._environment.torque]

    def _rhs(self, eta):
        J, Ji = self.J, self.J_inv

        eta = np.ascontiguousarray(eta, dtype=float).reshape(3)
        zero = np.zeros(3)

        env = self._environment
        if env is not None and not self.torque_fns:
            args = env._args

            def rhs(t, x):
                return _environment_rhs_nb(float(t), np.ascontiguousarray(x, dtype=float), J, Ji, eta,
                                           *args)

            return rhs

        def rhs(t, x):
            q, w = x[:4], x[4:]
            T = self.torque(t, q / np.sqrt(q @ q), w) if (self.torque_fns or self._named_fns) else zero
            # qd = ½ [0, ω] ⊗ q, ωd = J⁻¹ (T − ω × Jω) + η in a numba kernel (speed; same formula)
            return _truth_rhs_nb(np.ascontiguousarray(x, dtype=float),
                                 np.ascontiguousarray(T, dtype=float), J, Ji, eta)

        return rhs

    def simulate(self, t_s):
        """Attitudes and rates at the measurement times ``t_s`` (s): ``(q (N,4), ω (N,3))``."""
        t, t0 = _times(t_s, self.t0)
        self._sample_environment(t0, float(t[-1]))
        x0 = np.concatenate([self.q0, self.omega0])
        if self.eta_sigma == 0.0:
            x = integrate_truth(x0, t, self._rhs(np.zeros(3)), self.rtol, self.atol, t0=t0)
            return x[:, :4].copy(), x[:, 4:].copy()
        N = t.size
        out = np.empty((N, 7))
        x = x0
        t_prev = t0
        for k in range(N):
            dt = t[k] - t_prev
            if dt > 0:
                if self.noise == "piecewise_constant":
                    eta = self.rng.normal(0.0, 1.0, 3) * self.eta_sigma
                    x = integrate_truth(x, [t[k]], self._rhs(eta), self.rtol, self.atol, t0=t_prev)[0]
                else:
                    x = integrate_truth(x, [t[k]], self._rhs(np.zeros(3)), self.rtol, self.atol,
                                        t0=t_prev)[0]
                    # correlated impulse per axis: L L^T = σ² [[Δt³/3, Δt²/2], [Δt²/2, Δt]]
                    s = self.eta_sigma
                    l11 = s * np.sqrt(dt**3 / 3.0)
                    l21 = s * (dt**2 / 2.0) / np.sqrt(dt**3 / 3.0)
                    l22 = s * np.sqrt(dt - (dt**4 / 4.0) / (dt**3 / 3.0))
                    z = self.rng.normal(0.0, 1.0, (2, 3))
                    dth = l11 * z[0]
                    dw = l21 * z[0] + l22 * z[1]
                    q = rot.quat_mult(rot.rotvec_to_quat(dth), x[:4])
                    x = np.concatenate([q, x[4:] + dw])
            out[k] = x
            t_prev = t[k]
        out[:, :4] /= np.linalg.norm(out[:, :4], axis=1, keepdims=True)
        return out[:, :4].copy(), out[:, 4:].copy()
