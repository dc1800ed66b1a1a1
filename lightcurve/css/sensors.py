"""Coarse-sun-sensor (CSS) measurement model (O'Keefe 2015, eq. 2.19 and 2.21).

A cosine-type CSS is a photodiode whose output is proportional to the cosine of the angle
between its boresight (unit normal ``n̂``, body frame) and the Sun direction, inside a
field of view of half angle ``ψ``.  The model implemented here (eq. 2.21 in the form used
throughout this package) is, for sensor ``κ``::

    y_κ = C C_κ [ ν f_κ(ŝ) + Σ_j a_j f_κ(ĉ_j) ] + v_κ,       v_κ ~ N(0, σ²)
    f_κ(û) = n̂_κ'·û   if n̂_κ'·û ≥ cos ψ_κ and û is above the structure horizon, else 0

* ``ŝ``: unit Sun direction in body axes (spacecraft → Sun).
* ``ν``: lit fraction (1 in sunlight, 0 in umbra) — the direct term is zero in eclipse.
* ``ĉ_j``, ``a_j``: direction (body axes) and irradiance, in units of the solar irradiance
  at the spacecraft, of Earth-albedo cell ``j`` (eq. 2.15, see :mod:`lightcurve.css.albedo`).
* ``C``: common scale factor (solar-cell/photodiode degradation, distance to the Sun);
  ``C_κ``: individual scale factor of sensor ``κ``.
* ``n̂_κ'``: the *true* normal, i.e. the nominal normal perturbed by the misalignment angles
  of eq. 2.19: the azimuth and elevation of the normal are offset by ``δα_κ`` and ``δε_κ``,
  ``n̂' = [cos(ε+δε) cos(α+δα), cos(ε+δε) sin(α+δα), sin(ε+δε)]``.
* Structure horizon: an optional per-sensor plane normal ``b̂_κ`` (body axes); light from
  directions with ``b̂_κ·û < 0`` is blocked by the spacecraft body (zero vector: no cut-off).
* Outputs are clipped at zero (a photodiode current cannot be negative) unless
  ``clip=False``.

Signals are dimensionless: 1 is the output of a perfectly calibrated sensor facing the Sun.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numba
import numpy as np

from ..estimation.rng import as_generator

__all__ = [
    "CSSArray",
    "azel_to_normal",
    "normal_to_azel",
    "css_signals_nb",
    "css_signals_traj_nb",
]


def azel_to_normal(az_rad, el_rad):
    """Unit normal(s) (body axes) from azimuth (about +z from +x) and elevation (from the x-y
    plane toward +z), both in radians.  Returns an array of shape ``(..., 3)``."""
    az = np.asarray(az_rad, dtype=float)
    el = np.asarray(el_rad, dtype=float)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def normal_to_azel(n):
    """Azimuth and elevation (rad) of body-frame vector(s) ``n`` (..., 3); azimuth is 0 at
    the poles."""
    n = np.asarray(n, dtype=float)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    az = np.arctan2(n[..., 1], n[..., 0])
    el = np.arcsin(np.clip(n[..., 2], -1.0, 1.0))
    return az, el


@numba.njit(cache=True)
def _response(n, cos_fov, b, u):
    c = n[0] * u[0] + n[1] * u[1] + n[2] * u[2]
    if c < cos_fov or c <= 0.0:
        return 0.0
    if b[0] * u[0] + b[1] * u[1] + b[2] * u[2] < 0.0:
        return 0.0
    return c


@numba.njit(cache=True)
def css_signals_nb(normals, cos_fov, gains, horizon, s_b, lit, alb_dirs_b, alb_ratio):
    """Noise-free CSS outputs (eq. 2.21), numba kernel.

    normals (N,3) true unit normals, body; cos_fov (N,) cosines of the FOV half angles;
    gains (N,) products C·C_κ; horizon (N,3) structure-horizon plane normals (zeros: none);
    s_b (3,) unit Sun direction, body; lit: lit fraction in [0, 1]; alb_dirs_b (M,3) unit
    directions of albedo cells, body; alb_ratio (M,) their irradiance / solar irradiance.
    Returns (N,) outputs (dimensionless).
    """
    n_s = normals.shape[0]
    out = np.zeros(n_s)
    for k in range(n_s):
        acc = 0.0
        if lit > 0.0:
            acc += lit * _response(normals[k], cos_fov[k], horizon[k], s_b)
        for j in range(alb_dirs_b.shape[0]):
            acc += alb_ratio[j] * _response(normals[k], cos_fov[k], horizon[k], alb_dirs_b[j])
        out[k] = gains[k] * acc
    return out


@numba.njit(cache=True)
def css_signals_traj_nb(normals, cos_fov, gains, horizon, S_b, lit, alb_b):
    """Noise-free CSS outputs along a trajectory (no albedo cells; ``alb_b`` (K,N) holds the
    albedo part already projected onto each sensor, or zeros).  S_b (K,3) unit Sun directions
    in body axes, lit (K,) lit fractions.  Returns (K,N)."""
    K = S_b.shape[0]
    n_s = normals.shape[0]
    out = np.zeros((K, n_s))
    for i in range(K):
        for k in range(n_s):
            r = 0.0
            if lit[i] > 0.0:
                r = lit[i] * _response(normals[k], cos_fov[k], horizon[k], S_b[i])
            out[i, k] = gains[k] * (r + alb_b[i, k])
    return out


@dataclass(frozen=True)
class CSSArray:
    """A set of ``N`` coarse sun sensors fixed to the spacecraft body.

    Attributes
    ----------
    normals : ndarray (N, 3)
        Nominal unit boresight normals, body axes (what the flight software believes).
    fov_half_angle_rad : ndarray (N,)
        Field-of-view half angles ψ in (0, π/2] rad.
    scale_common : float
        Common scale factor C (dimensionless).
    scale_individual : ndarray (N,)
        Individual scale factors C_κ (dimensionless).
    misalignment_rad : ndarray (N, 2)
        True azimuth and elevation offsets (δα, δε) of each normal, rad (eq. 2.19).
    noise_sigma : float
        Standard deviation of the additive white output noise (dimensionless, full scale 1).
    horizon_normals : ndarray (N, 3)
        Structure-horizon plane normals (body axes); zero rows mean no cut-off.
    name : str
        Label used in reports.
    """

    normals: np.ndarray
    fov_half_angle_rad: np.ndarray
    scale_common: float = 1.0
    scale_individual: np.ndarray | None = None
    misalignment_rad: np.ndarray | None = None
    noise_sigma: float = 0.0
    horizon_normals: np.ndarray | None = None
    name: str = "css"
    sensor_names: tuple = field(default=())

    def __post_init__(self):
        n = np.array(self.normals, dtype=float, ndmin=2)
        if n.ndim != 2 or n.shape[1] != 3:
            raise ValueError(f"normals must have shape (N, 3), got {n.shape}")
        norms = np.linalg.norm(n, axis=1)
        if np.any(norms < 1e-12) or not np.all(np.isfinite(n)):
            raise ValueError("every CSS normal must be a finite non-zero vector")
        n = n / norms[:, None]
        N = n.shape[0]
        fov = np.broadcast_to(np.asarray(self.fov_half_angle_rad, dtype=float), (N,)).copy()
        if np.any(~(fov > 0.0)) or np.any(fov > np.pi / 2 + 1e-12):
            raise ValueError("FOV half angles must lie in (0, pi/2] rad")
        ci = np.ones(N) if self.scale_individual is None else np.broadcast_to(
            np.asarray(self.scale_individual, dtype=float), (N,)).copy()
        mis = np.zeros((N, 2)) if self.misalignment_rad is None else np.broadcast_to(
            np.asarray(self.misalignment_rad, dtype=float), (N, 2)).copy()
        hor = np.zeros((N, 3)) if self.horizon_normals is None else np.broadcast_to(
            np.asarray(self.horizon_normals, dtype=float), (N, 3)).copy()
        if not (np.isfinite(self.scale_common) and self.scale_common > 0):
            raise ValueError("scale_common must be a positive finite number")
        if np.any(~(ci > 0)):
            raise ValueError("individual scale factors must be positive")
        if not (self.noise_sigma >= 0):
            raise ValueError("noise_sigma must be >= 0")
        names = tuple(self.sensor_names) or tuple(f"css{k + 1}" for k in range(N))
        if len(names) != N:
            raise ValueError("sensor_names must have one entry per sensor")
        for attr, val in (("normals", n), ("fov_half_angle_rad", fov), ("scale_individual", ci),
                          ("misalignment_rad", mis), ("horizon_normals", hor),
                          ("sensor_names", names), ("scale_common", float(self.scale_common)),
                          ("noise_sigma", float(self.noise_sigma))):
            object.__setattr__(self, attr, val)

    # ------------------------------------------------------------------------------
    @property
    def n_sensors(self) -> int:
        """Number of sensors N."""
        return self.normals.shape[0]

    def true_normals(self) -> np.ndarray:
        """Misaligned unit normals (N, 3), body axes (eq. 2.19)."""
        az, el = normal_to_azel(self.normals)
        return azel_to_normal(az + self.misalignment_rad[:, 0], el + self.misalignment_rad[:, 1])

    def gains(self) -> np.ndarray:
        """Products C·C_κ (N,)."""
        return self.scale_common * self.scale_individual

    def with_errors(self, *, scale_common=None, scale_individual=None, misalignment_rad=None,
                    noise_sigma=None) -> "CSSArray":
        """A copy with some true error parameters replaced."""
        kw = {}
        if scale_common is not None:
            kw["scale_common"] = float(scale_common)
        if scale_individual is not None:
            kw["scale_individual"] = np.asarray(scale_individual, dtype=float)
        if misalignment_rad is not None:
            kw["misalignment_rad"] = np.asarray(misalignment_rad, dtype=float)
        if noise_sigma is not None:
            kw["noise_sigma"] = float(noise_sigma)
        return replace(self, **kw)

    def kernel_args(self, nominal: bool = False):
        """(normals, cos_fov, gains, horizon) for the numba kernels; ``nominal=True`` gives the
        error-free model the flight software assumes (nominal normals, unit gains)."""
        if nominal:
            return (self.normals.copy(), np.cos(self.fov_half_angle_rad), np.ones(self.n_sensors),
                    self.horizon_normals.copy())
        return (self.true_normals(), np.cos(self.fov_half_angle_rad), self.gains(),
                self.horizon_normals.copy())

    def signals(self, s_body, lit=1.0, albedo_dirs_body=None, albedo_ratio=None, *,
                rng=None, clip=True, nominal=False) -> np.ndarray:
        """CSS outputs for one or more Sun directions (eq. 2.21).

        Parameters
        ----------
        s_body : array (3,) or (K, 3)
            Sun direction(s) in body axes (normalised here).
        lit : float or array (K,)
            Lit fraction(s) ν in [0, 1]; 0 in umbra.
        albedo_dirs_body, albedo_ratio : arrays (M, 3), (M,), optional
            Albedo cells as returned by :func:`lightcurve.css.albedo.albedo_cells_in_view`
            rotated into body axes (only for a single ``s_body``).
        rng : numpy.random.Generator or int, optional
            Adds white noise of standard deviation ``noise_sigma`` when given.
        clip : bool
            Clip outputs at zero.
        nominal : bool
            Use the nominal (error-free) sensor model.

        Returns
        -------
        ndarray (N,) or (K, N)
        """
        s = np.asarray(s_body, dtype=float)
        single = s.ndim == 1
        S = np.atleast_2d(s)
        S = S / np.linalg.norm(S, axis=1, keepdims=True)
        K = S.shape[0]
        lit_a = np.broadcast_to(np.asarray(lit, dtype=float), (K,)).copy()
        normals, cos_fov, gains, hor = self.kernel_args(nominal)
        if albedo_dirs_body is not None and len(albedo_ratio):
            if not single:
                raise ValueError("albedo cells can only be given with a single Sun direction")
            out = css_signals_nb(normals, cos_fov, gains, hor, S[0], lit_a[0],
                                 np.ascontiguousarray(albedo_dirs_body, dtype=float),
                                 np.ascontiguousarray(albedo_ratio, dtype=float))[None, :]
        else:
            out = css_signals_traj_nb(normals, cos_fov, gains, hor, S, lit_a, np.zeros((K, self.n_sensors)))
        if rng is not None and self.noise_sigma > 0:
            out = out + as_generator(rng).normal(0.0, self.noise_sigma, out.shape)
        if clip:
            out = np.maximum(out, 0.0)
        return out[0] if single else out
