"""Model contexts: everything a forward model needs to evaluate measurements with effects.

:class:`ModelContext` (apparent magnitudes of a faceted object seen from ground sites) holds
the epochs, the measuring site of each epoch, the geometry (GCRS, metres), the shape, the
attitude at each epoch plus a way to evaluate it at shifted times, and the *effect state*
that physics effects switch on (:mod:`lightcurve.physics.registry`). Its
:meth:`ModelContext.magnitude` is the one place where the magnitude equation is evaluated:

    m = m_sun − 2.5 log10( ⟨ (ν F_sun + Σ F_extra) / |r_obs|² · (1 au / |r_sun|)² ⟩_exposure )

with ``F_sun = Σ_i A_i max(n̂_i·ŝ,0) max(n̂_i·ô,0) f_r,i`` (m² sr⁻¹, Bernard eq. 5.2–5.6 in
the consistent form of DESIGN.md, :func:`lightcurve.photometry.flux_factor`, or a facet
visibility-weighted version for self-shadowing), ``ν`` the illumination factor (baseline:
1 when any part of the solar disc is visible, 0 in umbra; with the penumbra effect: the
visible fraction of the solar disc), ``F_extra`` extra reflected light in the same units
(Earthshine, unmodelled glints; not multiplied by ν), and ⟨·⟩ the Gauss–Legendre average
over the exposure (exposure smearing; one node without it).

Times: row ``k`` is labelled ``t[k]`` (s since ``epoch_utc``; the mid-exposure time). An
effect can shift when the model is evaluated: a clock offset δ (the true mid-exposure time
is ``t + δ``) and the light time τ = |r_site − r_obj|/c (the object is evaluated at the
emission time ``t + δ − τ``; the site at ``t + δ``). Shifted states are computed from the
stored row: the object by a two-body RK4 step (|a_J2| ≈ 10⁻³ of the central term: < 20 m
over 60 s), the site by the Earth's rotation about the GCRS z axis (precession/nutation are
negligible over seconds), the Sun held fixed (it moves 0.04″/s), and the attitude by
constant-rate propagation ``q(t+Δ) = exp(ω Δ) ⊗ q(t)`` from the row's own truth quaternion
and body rate (exact for the controlled constant-rate truth; O(ω̇Δ²) otherwise) — or by the
``attitude_fn``/``orbit_fn`` callables when given.

:class:`CSSContext` is the same idea for coarse-sun-sensor voltages
(:mod:`lightcurve.css.sensors`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

__all__ = ["ModelContext", "CSSContext", "GeometryState", "C_LIGHT_M_S", "OMEGA_EARTH_RAD_S",
           "MU_EARTH_M3_S2", "gauss_legendre_offsets", "rotate_z"]

C_LIGHT_M_S = 299_792_458.0
"""Speed of light in vacuum, m/s (exact, SI)."""
OMEGA_EARTH_RAD_S = 7.292115e-5
"""Earth rotation rate (IERS conventional mean), rad/s."""
MU_EARTH_M3_S2 = 3.986004418e14
"""Earth gravitational parameter (WGS84/EGM96), m³/s²."""


#: unscaled CSS albedo signals by geometry/grid/sensor hash (:meth:`CSSContext.albedo_signal`)
_ALBEDO_CACHE: dict = {}


def rotate_z(v, angle_rad):
    """Rotate vectors (N,3) actively about +z by ``angle_rad`` (N,) (right-handed)."""
    v = np.asarray(v, float)
    a = np.asarray(angle_rad, float)
    c, s = np.cos(a), np.sin(a)
    out = v.copy()
    out[..., 0] = c * v[..., 0] - s * v[..., 1]
    out[..., 1] = s * v[..., 0] + c * v[..., 1]
    return out


def _two_body(r, v, dt):
    """Two-body RK4 propagation of (N,3) states by dt (N,) seconds in ≤ 10 s sub-steps."""
    dt = np.asarray(dt, float)
    nstep = max(1, int(np.ceil(np.max(np.abs(dt)) / 10.0))) if dt.size else 1
    h = (dt / nstep)[:, None]

    def acc(x):
        rn = np.linalg.norm(x, axis=1, keepdims=True)
        return -MU_EARTH_M3_S2 * x / rn**3

    r = r.copy()
    v = v.copy()
    for _ in range(nstep):
        k1r, k1v = v, acc(r)
        k2r, k2v = v + 0.5 * h * k1v, acc(r + 0.5 * h * k1r)
        k3r, k3v = v + 0.5 * h * k2v, acc(r + 0.5 * h * k2r)
        k4r, k4v = v + h * k3v, acc(r + h * k3r)
        r = r + h / 6.0 * (k1r + 2 * k2r + 2 * k3r + k4r)
        v = v + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return r, v


def _estimate_velocity(t, r):
    """Velocity (N,3) by finite differences of positions at the distinct times; NaN if < 2."""
    tu, idx = np.unique(t, return_index=True)
    if tu.size < 2:
        return np.full_like(r, np.nan)
    ru = r[idx]
    vu = np.gradient(ru, tu, axis=0, edge_order=2 if tu.size > 2 else 1)
    return vu[np.searchsorted(tu, t)]


def gauss_legendre_offsets(n: int):
    """Nodes x_j ∈ (−1, 1) and weights w_j (Σ w_j = 1) of an n-point Gauss–Legendre average.

    ``⟨f⟩ = Σ_j w_j f(t + x_j T/2)`` is the exact mean of f over [t − T/2, t + T/2] for
    polynomials of degree ≤ 2n − 1.
    """
    x, w = np.polynomial.legendre.leggauss(int(n))
    return x, w / 2.0


@dataclass
class GeometryState:
    """Geometry and attitude at the evaluation instants of every row (GCRS, SI units).

    ``dt_obj`` (N,) is the object's time shift from ``t`` (emission), ``dt_site`` the site's
    (reception); q (N,4) inertial→body; r_* (N,3) m; s_unit, o_unit (N,3) unit object→Sun
    and object→observer; range_obs, range_sun (N,) m.
    """

    dt_obj: np.ndarray
    dt_site: np.ndarray
    q: np.ndarray
    r_obj: np.ndarray
    v_obj: np.ndarray
    r_site: np.ndarray
    r_sun: np.ndarray
    s_unit: np.ndarray
    o_unit: np.ndarray
    range_obs: np.ndarray
    range_sun: np.ndarray
    _memo: dict = field(default_factory=dict, repr=False, compare=False)

    def body_directions(self):
        """(s_body, o_body), each (N,1,3): the unit directions in body axes (computed once)."""
        if "body" not in self._memo:
            from ..photometry.magnitude import body_directions

            self._memo["body"] = body_directions(self.q, self.s_unit, self.o_unit)
        return self._memo["body"]


@dataclass
class ModelContext:
    """Baseline measurement model of a lightcurve plus the switched-on effect state.

    Data (N rows, K sites): ``epoch_utc`` (ISO UTC); ``t`` (N,) s since epoch (mid-exposure
    labels); ``site_index`` (N,) int; ``site_names`` (K); ``shape`` (:class:`Shape`); ``q``
    (N,4) inertial→body attitude at ``t``; ``omega`` (N,3) body rates, rad/s, body axes (for
    time shifts; may be None with ``attitude_fn``); ``r_obj_eci_m``, ``v_obj_eci_m_s``,
    ``r_site_eci_m``, ``r_sun_eci_m`` (N,3) GCRS; ``elevation_rad`` (N,) object elevation at
    the site; ``sun_mag`` (Sun's apparent magnitude at 1 au); ``ignore_eclipse`` (treat the
    object as sunlit); ``attitude_fn(t) -> (N,4)`` and ``orbit_fn(t) -> (r, v)`` optional
    callables at absolute times (s since epoch); ``camera_index`` (N,) int and
    ``camera_names`` (C) optional photometric channels (a camera or detector whose
    calibration is its own, e.g. for per-camera zero points); without them every site is one
    camera named after the site.

    Effect state (set by effects through :meth:`with_state`): ``penumbra``,
    ``shadow_height_m``, ``time_offset_s`` (N,), ``light_time``, ``exposure_s`` (N,),
    ``exposure_nodes``, ``flux_model`` (callable(ctx, state, s_body, o_body) -> (N,) flux
    replacing the facet sum), ``extra_flux`` (tuple of callables(ctx, state) -> (N,) flux,
    m² sr⁻¹ in units of the solar irradiance at the object).
    """

    epoch_utc: str
    t: np.ndarray
    site_index: np.ndarray
    site_names: list
    shape: object
    q: np.ndarray
    omega: np.ndarray | None
    r_obj_eci_m: np.ndarray
    v_obj_eci_m_s: np.ndarray | None
    r_site_eci_m: np.ndarray
    r_sun_eci_m: np.ndarray
    elevation_rad: np.ndarray | None = None
    sun_mag: float = -26.74
    ignore_eclipse: bool = False
    attitude_fn: object = None
    orbit_fn: object = None
    camera_index: np.ndarray | None = None
    camera_names: list | None = None
    # -- effect state --
    penumbra: bool = False
    shadow_height_m: float = 0.0
    time_offset_s: np.ndarray | None = None
    light_time: bool = False
    exposure_s: np.ndarray | None = None
    exposure_nodes: int = 12
    flux_model: object = None
    extra_flux: tuple = ()
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        self.t = np.atleast_1d(np.asarray(self.t, float))
        n = self.t.size
        self.site_index = np.broadcast_to(np.asarray(self.site_index, np.int64), (n,)).copy()
        self.site_names = list(self.site_names)
        for name in ("r_obj_eci_m", "r_site_eci_m", "r_sun_eci_m"):
            a = np.asarray(getattr(self, name), float).reshape(-1, 3)
            if a.shape != (n, 3):
                raise ValueError(f"{name} must have shape ({n}, 3), got {a.shape}")
            setattr(self, name, a)
        q = np.asarray(self.q, float).reshape(-1, 4)
        if q.shape != (n, 4):
            raise ValueError(f"q must have shape ({n}, 4), got {q.shape}")
        self.q = q
        if self.omega is not None:
            self.omega = np.asarray(self.omega, float).reshape(n, 3)
        v = None if self.v_obj_eci_m_s is None else np.asarray(self.v_obj_eci_m_s, float).reshape(n, 3)
        if v is None or not np.all(np.isfinite(v)):
            v = _estimate_velocity(self.t, self.r_obj_eci_m)
        self.v_obj_eci_m_s = v
        if self.elevation_rad is not None:
            self.elevation_rad = np.asarray(self.elevation_rad, float).reshape(n)
        if n and (self.site_index.min() < 0 or self.site_index.max() >= max(len(self.site_names), 1)):
            raise ValueError("site_index out of range of site_names")
        if (self.camera_index is None) != (self.camera_names is None):
            raise ValueError("camera_index and camera_names go together")
        if self.camera_index is not None:
            self.camera_index = np.broadcast_to(np.asarray(self.camera_index, np.int64), (n,)).copy()
            self.camera_names = list(self.camera_names)
            if n and (self.camera_index.min() < 0 or self.camera_index.max() >= len(self.camera_names)):
                raise ValueError("camera_index out of range of camera_names")

    # -- constructors ------------------------------------------------------------------------
    @classmethod
    def from_geometry(cls, geo, shape, q, omega=None, *, sun_mag: float = -26.74,
                      ignore_eclipse: bool = False, attitude_fn=None, orbit_fn=None,
                      site_names=None) -> "ModelContext":
        """Context from an :class:`~lightcurve.geometry.observation.ObservationGeometry`."""
        names = site_names if site_names is not None else [s.id for s in geo.sites]
        return cls(epoch_utc=geo.epoch_utc, t=geo.t, site_index=geo.site_index, site_names=names,
                   shape=shape, q=q, omega=omega, r_obj_eci_m=geo.r_obj_eci_m,
                   v_obj_eci_m_s=geo.v_obj_eci_m_s, r_site_eci_m=geo.r_site_eci_m,
                   r_sun_eci_m=geo.r_sun_eci_m, elevation_rad=geo.elevation_rad, sun_mag=sun_mag,
                   ignore_eclipse=ignore_eclipse, attitude_fn=attitude_fn, orbit_fn=orbit_fn)

    @classmethod
    def from_lightcurve(cls, lc, shape, q=None, omega=None, *, sun_mag=None,
                        ignore_eclipse=None, attitude_fn=None, orbit_fn=None) -> "ModelContext":
        """Context from a :class:`~lightcurve.io.Lightcurve` (truth attitude by default)."""
        q = lc.truth_q if q is None else q
        omega = lc.truth_omega_rad_s if omega is None else omega
        if q is None and attitude_fn is None:
            raise ValueError("the lightcurve has no truth attitude: pass q or attitude_fn")
        if q is None:
            q = attitude_fn(np.asarray(lc.t, float))
        sm = float(lc.attrs.get("sun_mag", -26.74)) if sun_mag is None else float(sun_mag)
        ie = bool(int(lc.attrs.get("ignore_eclipse", 0))) if ignore_eclipse is None else bool(ignore_eclipse)
        return cls(epoch_utc=lc.epoch_utc, t=lc.t, site_index=lc.site, site_names=lc.site_names,
                   shape=shape, q=q, omega=omega, r_obj_eci_m=lc.r_obj_eci_m, v_obj_eci_m_s=None,
                   r_site_eci_m=lc.r_site_eci_m, r_sun_eci_m=lc.r_sun_eci_m,
                   elevation_rad=lc.elevation_rad, sun_mag=sm, ignore_eclipse=ie,
                   attitude_fn=attitude_fn, orbit_fn=orbit_fn)

    # -- basic properties -------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def n_sites(self) -> int:
        return len(self.site_names)

    @property
    def n_cameras(self) -> int:
        """Number of cameras (= sites when the context has no camera column)."""
        return self.n_sites if self.camera_names is None else len(self.camera_names)

    @property
    def camera_ids(self) -> list:
        """Camera names (the site names when the context has no camera column)."""
        return list(self.site_names if self.camera_names is None else self.camera_names)

    @property
    def camera_index_rows(self) -> np.ndarray:
        """(N,) camera index of each row (the site index without a camera column)."""
        return self.site_index if self.camera_index is None else self.camera_index

    def camera_values(self, per_camera) -> np.ndarray:
        """Per-row values (N,) from a per-camera array (C,) or a scalar."""
        v = np.asarray(per_camera, float)
        return np.full(len(self), float(v)) if v.ndim == 0 else v[self.camera_index_rows]

    @property
    def airmass(self) -> np.ndarray:
        """Kasten & Young (1989) relative air mass at each row (NaN below the horizon)."""
        from ..geometry.visibility import airmass_kasten_young

        if self.elevation_rad is None:
            raise ValueError("this context has no elevation_rad (needed for the air mass)")
        return airmass_kasten_young(self.elevation_rad)

    #: fields whose change leaves the geometry (:meth:`state`) unchanged
    _GEOMETRY_NEUTRAL = frozenset({"shape", "penumbra", "shadow_height_m", "ignore_eclipse",
                                   "flux_model", "extra_flux", "exposure_s", "exposure_nodes",
                                   "sun_mag", "camera_index", "camera_names"})

    def with_state(self, **changes) -> "ModelContext":
        """A copy with effect-state fields replaced.

        Changes that leave the geometry unchanged (the shape, illumination, extra flux …)
        share the cache of :meth:`state` results, so refits of reflection or brightness
        parameters do not recompute positions and body-frame directions.
        """
        if set(changes) <= self._GEOMETRY_NEUTRAL:
            return replace(self, _cache=self._cache, **changes)
        return replace(self, _cache={}, **changes)

    def site_values(self, per_site) -> np.ndarray:
        """Per-row values (N,) from a per-site array (K,) or a scalar."""
        v = np.asarray(per_site, float)
        return np.full(len(self), float(v)) if v.ndim == 0 else v[self.site_index]

    # -- shifted states ---------------------------------------------------------------------
    def attitude_at(self, dt) -> np.ndarray:
        """Attitude (N,4) at ``t + dt`` (dt (N,) s): ``attitude_fn`` or constant-rate propagation."""
        dt = np.broadcast_to(np.asarray(dt, float), self.t.shape)
        if not np.any(dt):
            return self.q
        if self.attitude_fn is not None:
            return np.asarray(self.attitude_fn(self.t + dt), float).reshape(-1, 4)
        if self.omega is None:
            raise ValueError("evaluating the attitude at shifted times needs omega or attitude_fn")
        from ..dynamics.kinematics import propagate_constant_rate

        return propagate_constant_rate(self.q, self.omega, dt)

    def object_at(self, dt):
        """Object position and velocity (N,3) at ``t + dt`` (two-body RK4 or ``orbit_fn``)."""
        dt = np.broadcast_to(np.asarray(dt, float), self.t.shape)
        if not np.any(dt):
            return self.r_obj_eci_m, self.v_obj_eci_m_s
        if self.orbit_fn is not None:
            r, v = self.orbit_fn(self.t + dt)
            return np.asarray(r, float).reshape(-1, 3), np.asarray(v, float).reshape(-1, 3)
        if not np.all(np.isfinite(self.v_obj_eci_m_s)):
            raise ValueError("object velocity unknown (give v_obj_eci_m_s, orbit_fn or >= 2 epochs)")
        return _two_body(self.r_obj_eci_m, self.v_obj_eci_m_s, dt)

    def state(self, dt=0.0) -> GeometryState:
        """Geometry and attitude for the reception times ``t + dt`` (+ clock offset, light time).

        Results are cached per ``dt`` (the context's time-offset and light-time state are
        fixed for its lifetime; :meth:`with_state` clears the cache when they change).
        """
        dta = np.asarray(dt, float)
        key = ("state", dta.tobytes(), dta.shape)
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        st = self._state(dt)
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[key] = st
        return st

    def _state(self, dt=0.0) -> GeometryState:
        n = len(self)
        dt_site = np.broadcast_to(np.asarray(dt, float), (n,)).astype(float)
        if self.time_offset_s is not None:
            dt_site = dt_site + self.time_offset_s
        r_site = self.r_site_eci_m if not np.any(dt_site) else rotate_z(
            self.r_site_eci_m, OMEGA_EARTH_RAD_S * dt_site)
        dt_obj = dt_site
        if self.light_time:
            r_o, _ = self.object_at(dt_obj)
            tau = np.linalg.norm(r_site - r_o, axis=1) / C_LIGHT_M_S
            r_o, _ = self.object_at(dt_site - tau)
            tau = np.linalg.norm(r_site - r_o, axis=1) / C_LIGHT_M_S
            dt_obj = dt_site - tau
        r_obj, v_obj = self.object_at(dt_obj)
        q = self.attitude_at(dt_obj)
        d_sun = self.r_sun_eci_m - r_obj
        d_obs = r_site - r_obj
        rs = np.linalg.norm(d_sun, axis=1)
        ro = np.linalg.norm(d_obs, axis=1)
        return GeometryState(dt_obj=dt_obj, dt_site=dt_site, q=q, r_obj=r_obj, v_obj=v_obj,
                             r_site=r_site, r_sun=self.r_sun_eci_m, s_unit=d_sun / rs[:, None],
                             o_unit=d_obs / ro[:, None], range_obs=ro, range_sun=rs)

    def illumination(self, st: GeometryState) -> np.ndarray:
        """Illumination factor ν (N,): 1/0 lit-or-umbra (baseline) or the penumbral fraction."""
        from ..geometry.eclipse import R_EARTH_SHADOW_M, lit_fraction

        if self.ignore_eclipse:
            return np.ones(len(self))
        key = ("nu", bool(self.penumbra), float(self.shadow_height_m) if self.penumbra else 0.0)
        hit = st._memo.get(key)
        if hit is not None:
            return hit
        if self.penumbra:
            nu = lit_fraction(st.r_obj, st.r_sun, "conical",
                              earth_radius_m=R_EARTH_SHADOW_M + self.shadow_height_m)
        else:
            nu = (lit_fraction(st.r_obj, st.r_sun, "conical") > 0.0).astype(float)
        if len(st._memo) > 32:
            st._memo.clear()
        st._memo[key] = nu
        return nu

    def sun_flux(self, st: GeometryState) -> np.ndarray:
        """Facet-summed solar flux factor (N,) m² sr⁻¹ (ν not applied)."""
        from ..photometry.magnitude import flux_factor

        sb, ob = st.body_directions()
        if self.flux_model is not None:
            return np.asarray(self.flux_model(self, st, sb[:, 0], ob[:, 0]), float)
        return flux_factor(self.shape, sb, ob)[:, 0]

    # -- the measurement model --------------------------------------------------------------
    def irradiance_ratio(self, t_shift=None, lit_fraction=None, extra_flux=None) -> np.ndarray:
        """⟨(ν F_sun + ΣF_extra) / |r_obs|² · (au/|r_sun|)²⟩ (N,), m⁰ sr⁻¹ (module docstring).

        ``t_shift`` (s, scalar or (N,)) evaluates the model at shifted reception times;
        ``lit_fraction`` (N,) overrides ν; ``extra_flux`` (N,) m² sr⁻¹ adds light (applied at
        every exposure node).
        """
        from ..photometry.magnitude import AU_M

        base = np.zeros(len(self)) if t_shift is None else np.broadcast_to(
            np.asarray(t_shift, float), (len(self),))
        if self.exposure_s is not None and np.any(self.exposure_s > 0):
            x, w = gauss_legendre_offsets(self.exposure_nodes)
            offsets = [base + xj * 0.5 * self.exposure_s for xj in x]
        else:
            offsets, w = [base], np.array([1.0])
        total = np.zeros(len(self))
        for off, wj in zip(offsets, w):
            st = self.state(off)
            nu = self.illumination(st) if lit_fraction is None else np.asarray(lit_fraction, float)
            F = nu * self.sun_flux(st)
            for fn in self.extra_flux:
                F = F + fn(self, st)
            if extra_flux is not None:
                F = F + extra_flux
            total += wj * F / st.range_obs**2 * (AU_M / st.range_sun) ** 2
        return total

    def magnitude(self, t_shift=None, lit_fraction=None, extra_flux=None) -> np.ndarray:
        """Apparent magnitudes (N,) with the switched-on effects; +inf where nothing is seen."""
        r = self.irradiance_ratio(t_shift, lit_fraction, extra_flux)
        with np.errstate(divide="ignore"):
            m = self.sun_mag - 2.5 * np.log10(np.where(r > 0, r, 1.0))
        return np.where(r > 0, m, np.inf)

    def evaluate(self) -> np.ndarray:
        """The measurements of this context: :meth:`magnitude` with default arguments."""
        return self.magnitude()


@dataclass
class CSSContext:
    """Coarse-sun-sensor measurement model plus the effect state (K epochs, S sensors).

    ``array`` (:class:`~lightcurve.css.sensors.CSSArray`, the model's sensors); ``t`` (K,) s
    since ``epoch_utc``; ``q`` (K,4) inertial→body; ``r_eci_m`` (K,3) spacecraft GCRS
    position; ``sun_eci_unit`` (K,3) unit spacecraft→Sun, GCRS; ``lit`` (K,) lit fraction.
    Effect state: ``albedo_grid`` (:class:`~lightcurve.earth.albedo.AlbedoGrid`) with
    ``albedo_scale``; ``fault`` = (sensor index, gain, start time s) or None.
    Outputs (K,S) are clipped at zero (photodiode currents), O'Keefe eq. 2.21.
    """

    array: object
    t: np.ndarray
    epoch_utc: str
    q: np.ndarray
    r_eci_m: np.ndarray
    sun_eci_unit: np.ndarray
    lit: np.ndarray
    albedo_grid: object = None
    albedo_scale: float = 1.0
    fault: tuple | None = None

    def __post_init__(self):
        self.t = np.atleast_1d(np.asarray(self.t, float))
        k = self.t.size
        self.q = np.asarray(self.q, float).reshape(k, 4)
        self.r_eci_m = np.asarray(self.r_eci_m, float).reshape(k, 3)
        s = np.asarray(self.sun_eci_unit, float).reshape(k, 3)
        self.sun_eci_unit = s / np.linalg.norm(s, axis=1, keepdims=True)
        self.lit = np.broadcast_to(np.asarray(self.lit, float), (k,)).copy()

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def n_sensors(self) -> int:
        return self.array.n_sensors

    n_sites = 0

    def with_state(self, **changes) -> "CSSContext":
        return replace(self, **changes)

    def albedo_signal(self) -> np.ndarray:
        """Albedo irradiance on each (true) sensor, (K,S), units of solar irradiance (eq. 2.15).

        The unscaled signal depends only on the geometry, the grid and the sensors' normals,
        fields of view and horizons; it is cached (a few recent sets), so fits of the albedo
        scale or of other effects do not repeat the Earth-grid sums.
        """
        K, S = len(self), self.n_sensors
        if self.albedo_grid is None:
            return np.zeros((K, S))
        import hashlib

        normals, cos_fov, _, hor = self.array.kernel_args(False)
        h = hashlib.blake2b(digest_size=16)
        for a in (self.t, self.q, self.r_eci_m, self.sun_eci_unit, normals, cos_fov, hor,
                  self.albedo_grid.rho_area_m2, self.albedo_grid.centers_m):
            h.update(np.ascontiguousarray(a, float).tobytes())
        h.update(self.epoch_utc.encode())
        key = h.hexdigest()
        hit = _ALBEDO_CACHE.get(key)
        if hit is None:
            hit = self._albedo_signal_unscaled()
            if len(_ALBEDO_CACHE) >= 16:
                _ALBEDO_CACHE.pop(next(iter(_ALBEDO_CACHE)))
            _ALBEDO_CACHE[key] = hit
        return hit * self.albedo_scale

    def _albedo_signal_unscaled(self) -> np.ndarray:
        from ..css.albedo import albedo_on_sensors_nb
        from ..earth.albedo import earth_rotation_angle
        from ..rotations import quat_rotate_inv

        K, S = len(self), self.n_sensors
        out = np.zeros((K, S))
        g = self.albedo_grid
        theta = earth_rotation_angle(self.epoch_utc, self.t)
        normals, cos_fov, _, hor = self.array.kernel_args(False)
        for i in range(K):
            # body → ECI (Aᵀ), then ECI → Earth-fixed: r_E = R3(θ) r_I (passive; active −θ)
            n_e = rotate_z(quat_rotate_inv(self.q[i], normals), -theta[i])
            h_e = rotate_z(quat_rotate_inv(self.q[i], hor), -theta[i])
            r_e = rotate_z(self.r_eci_m[i][None], -theta[i])[0]
            s_e = rotate_z(self.sun_eci_unit[i][None], -theta[i])[0]
            out[i] = albedo_on_sensors_nb(g.centers_m, g.normals, g.rho_area_m2, r_e, s_e,
                                          np.ascontiguousarray(n_e), cos_fov,
                                          np.ascontiguousarray(h_e))
        return out

    def voltages(self) -> np.ndarray:
        """Noise-free outputs (K,S) of the sensors with the switched-on effects."""
        from ..css.sensors import css_signals_traj_nb
        from ..rotations import quat_rotate

        s_b = np.ascontiguousarray(quat_rotate(self.q, self.sun_eci_unit))
        normals, cos_fov, gains, hor = self.array.kernel_args(False)
        y = css_signals_traj_nb(np.ascontiguousarray(normals), cos_fov, gains,
                                np.ascontiguousarray(hor), s_b, self.lit,
                                np.ascontiguousarray(self.albedo_signal()))
        if self.fault is not None:
            k, gain, t0 = self.fault
            m = self.t >= t0
            y[m, int(k)] *= gain
        return np.maximum(y, 0.0)

    def evaluate(self) -> np.ndarray:
        return self.voltages()
