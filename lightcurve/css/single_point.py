"""Single-point sun-direction estimators (O'Keefe 2015, §3.1): WAVG, LSMN, WLSMN.

All estimators use only the current CSS outputs ``y`` (N,) and the nominal sensor normals
``n̂_κ`` (N,3, body axes); sensors with ``y_κ > threshold`` are "active".  They return a unit
Sun-direction estimate in body axes, or zeros when no sensor is active.

* WAVG (eq. 3.3): normalised weighted vector average ``ŝ ∝ Σ y_κ n̂_κ``.
* LSMN (eq. 3.9-3.10): with ``H`` the (m,3) matrix of active normals, least squares
  ``d = (HᵀH)⁻¹Hᵀy`` when ``m ≥ 3`` and ``HᵀH`` is well conditioned, otherwise the minimum
  norm solution ``d = Hᵀ(HHᵀ)⁻¹y`` (for m < 3 the problem is underdetermined).
* WLSMN (eq. 3.12): as LSMN with the least-squares branch weighted by ``W = diag(y_κ)``:
  ``d = (HᵀWH)⁻¹HᵀWy`` — brighter sensors are trusted more (they are further from the
  grazing, albedo-dominated part of the cosine curve).

Noise-free error maps over all Sun directions (figs. 3.1-3.2) come from :func:`error_map`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..core.kalman import inverse_nb

__all__ = ["wavg_nb", "lsmn_nb", "run_single_point_nb", "estimate", "SINGLE_POINT_METHODS",
           "error_map", "ErrorMap",
           "plot_error_map", "angle_deg"]

SINGLE_POINT_METHODS = ("wavg", "lsmn", "wlsmn")
_METHOD_ID = {"wavg": 0, "lsmn": 1, "wlsmn": 2}


@numba.njit(cache=True)
def wavg_nb(y, normals, threshold):
    """WAVG (eq. 3.3): unit Σ y_κ n̂_κ over active sensors; zeros if none."""
    s = np.zeros(3)
    for k in range(y.shape[0]):
        if y[k] > threshold:
            for i in range(3):
                s[i] += y[k] * normals[k, i]
    nrm = np.sqrt(s[0] ** 2 + s[1] ** 2 + s[2] ** 2)
    if nrm > 0:
        s /= nrm
    return s


@numba.njit(cache=True)
def lsmn_nb(y, normals, threshold, weighted):
    """LSMN (eq. 3.9-3.10) or, with ``weighted``, WLSMN (eq. 3.12); unit result or zeros."""
    idx = np.empty(y.shape[0], dtype=np.int64)
    m = 0
    for k in range(y.shape[0]):
        if y[k] > threshold:
            idx[m] = k
            m += 1
    d = np.zeros(3)
    if m == 0:
        return d
    H = np.empty((m, 3))
    yy = np.empty(m)
    w = np.empty(m)
    for i in range(m):
        H[i] = normals[idx[i]]
        yy[i] = y[idx[i]]
        w[i] = y[idx[i]] if weighted else 1.0
    done = False
    if m >= 3:
        A = np.zeros((3, 3))
        b = np.zeros(3)
        for i in range(m):
            for r in range(3):
                b[r] += H[i, r] * w[i] * yy[i]
                for c in range(3):
                    A[r, c] += H[i, r] * w[i] * H[i, c]
        # well conditioned?  det(A) against (trace/3)³ bounds the smallest/largest
        # eigenvalue ratio from below (AM-GM), so this accepts only clearly full-rank H
        det = (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
               - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
               + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))
        tr = (A[0, 0] + A[1, 1] + A[2, 2]) / 3.0
        if det > 1e-6 * tr * tr * tr:
            Ai, ok = inverse_nb(A)
            if ok:
                d = Ai @ b
                done = True
    if not done:
        # minimum norm: d = Hᵀ (H Hᵀ)⁻¹ y; a tiny ridge copes with parallel normals
        G = H @ H.T
        for i in range(m):
            G[i, i] += 1e-10
        Gi, ok = inverse_nb(G)
        lam = Gi @ yy
        d = H.T @ lam
    nrm = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    if nrm > 0:
        d = d / nrm
    return d


@numba.njit(cache=True)
def run_single_point_nb(method_id, Y, normals, threshold):
    """Single-point estimates for every row of Y (K,N) in one compiled loop; method_id 0
    WAVG, 1 LSMN, 2 WLSMN.  Returns (K,3) unit vectors (zeros where no sensor is active)."""
    out = np.zeros((Y.shape[0], 3))
    for i in range(Y.shape[0]):
        if method_id == 0:
            out[i] = wavg_nb(Y[i], normals, threshold)
        else:
            out[i] = lsmn_nb(Y[i], normals, threshold, method_id == 2)
    return out


def estimate(method: str, y, normals, threshold: float = 0.0) -> np.ndarray:
    """Sun-direction estimate(s) (body axes, unit) from CSS outputs ``y`` (N,) or (K,N).

    ``method`` is 'wavg', 'lsmn' or 'wlsmn'; ``threshold`` is the activity threshold on the
    (dimensionless) outputs.  Rows with no active sensor give zeros.
    """
    if method not in _METHOD_ID:
        raise ValueError(f"unknown single-point method {method!r}; "
                         f"allowed: {', '.join(SINGLE_POINT_METHODS)}")
    Y = np.ascontiguousarray(np.atleast_2d(np.asarray(y, dtype=float)))
    n = np.ascontiguousarray(normals, dtype=float)
    out = run_single_point_nb(_METHOD_ID[method], Y, n, float(threshold))
    return out[0] if np.ndim(y) == 1 else out


def angle_deg(a, b):
    """Angle(s) in degrees between vectors ``a`` and ``b`` (..., 3); 180 for zero vectors."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    na = np.linalg.norm(a, axis=-1)
    nb = np.linalg.norm(b, axis=-1)
    c = np.sum(a * b, axis=-1) / np.where(na * nb > 0, na * nb, 1.0)
    ang = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
    return np.where(na * nb > 0, ang, 180.0)


@dataclass
class ErrorMap:
    """Noise-free angular error (deg) of a method over Sun azimuth/elevation in body axes.

    az_deg (n_az,), el_deg (n_el,), error_deg (n_el, n_az), n_active (n_el, n_az)."""

    method: str
    configuration: str
    az_deg: np.ndarray
    el_deg: np.ndarray
    error_deg: np.ndarray
    n_active: np.ndarray


def error_map(css, method: str, *, n_az: int = 121, n_el: int = 61, threshold: float = 0.0,
              plot: bool = False):
    """Noise-free error map of a single-point method (O'Keefe figs. 3.1-3.2).

    Uses the nominal, error-free sensor model (no albedo, no noise), so the errors shown are
    the ones caused by the underdetermined coverage alone.  Returns an :class:`ErrorMap`,
    or ``(ErrorMap, matplotlib Figure)`` when ``plot`` is true.
    """
    from .sensors import azel_to_normal

    az = np.linspace(-180.0, 180.0, n_az)
    el = np.linspace(-90.0, 90.0, n_el)
    AZ, EL = np.meshgrid(np.radians(az), np.radians(el))
    S = azel_to_normal(AZ, EL).reshape(-1, 3)
    Y = css.signals(S, nominal=True)
    est = estimate(method, Y, css.normals, threshold)
    err = angle_deg(est, S).reshape(n_el, n_az)
    nact = (Y > threshold).sum(axis=1).reshape(n_el, n_az)
    em = ErrorMap(method, css.name, az, el, err, nact)
    if plot:
        return em, plot_error_map(em)
    return em


def plot_error_map(em: ErrorMap):
    """A matplotlib figure of an :class:`ErrorMap` (Agg backend safe)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6))
    pc = ax.pcolormesh(em.az_deg, em.el_deg, em.error_deg, shading="auto", cmap="viridis")
    fig.colorbar(pc, ax=ax, label="angular error (deg)")
    ax.set_xlabel("Sun azimuth in body axes (deg)")
    ax.set_ylabel("Sun elevation in body axes (deg)")
    ax.set_title(f"{em.method.upper()} noise-free error, {em.configuration}")
    fig.tight_layout()
    return fig
