"""Input validation shared by the dynamics modules (programmer-facing ``ValueError``s)."""

from __future__ import annotations

import numpy as np

from .. import rotations as rot

UNIT_VEC_TOL = 1e-6


def vec3(v, name: str) -> np.ndarray:
    """Finite float array of shape (..., 3)."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected an array of numbers") from None
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape (..., 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return a


def unit_vec3(v, name: str) -> np.ndarray:
    a = vec3(v, name)
    n = np.linalg.norm(a, axis=-1)
    if np.any(np.abs(n - 1.0) > UNIT_VEC_TOL):
        raise ValueError(f"{name}: not a unit vector (norm {float(np.max(np.abs(n - 1))):.3g} away from 1)")
    return a


def finite_scalar(x, name: str, *, positive: bool = False, nonneg: bool = False) -> float:
    try:
        f = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {x!r}") from None
    if not np.isfinite(f):
        raise ValueError(f"{name}: must be finite, got {f}")
    if positive and f <= 0:
        raise ValueError(f"{name}: must be > 0, got {f}")
    if nonneg and f < 0:
        raise ValueError(f"{name}: must be >= 0, got {f}")
    return f


def one_of(value, name: str, allowed):
    """``value`` if it is one of ``allowed`` (ValueError naming ``name`` and the choices)."""
    if value not in allowed:
        raise ValueError(f"{name}: expected {' or '.join(map(repr, allowed))}, got {value!r}")
    return value


def facets(areas_m2, normals_body, centers_body_m):
    """Validate facet arrays: areas (F,) >= 0, unit normals (F,3), centres of pressure (F,3)."""
    A = np.atleast_1d(np.asarray(areas_m2, dtype=float))
    if A.ndim != 1:
        raise ValueError(f"areas_m2: expected shape (F,), got {A.shape}")
    F = A.shape[0]
    if not np.all(np.isfinite(A)) or np.any(A < 0):
        raise ValueError("areas_m2: areas must be finite and >= 0")
    n = unit_vec3(normals_body, "normals_body")
    c = vec3(centers_body_m, "centers_body_m")
    if n.shape != (F, 3):
        raise ValueError(f"normals_body: expected shape ({F}, 3) to match areas_m2, got {n.shape}")
    if c.shape != (F, 3):
        raise ValueError(f"centers_body_m: expected shape ({F}, 3) to match areas_m2, got {c.shape}")
    return A, n, c


def per_facet(x, F: int, name: str, lo: float = 0.0, hi: float = 1.0) -> np.ndarray:
    """Scalar or (F,) coefficient array within [lo, hi]."""
    a = np.asarray(x, dtype=float)
    a = np.broadcast_to(a, (F,)).copy() if a.ndim == 0 else a
    if a.shape != (F,):
        raise ValueError(f"{name}: expected a scalar or shape ({F},), got {a.shape}")
    if not np.all(np.isfinite(a)) or np.any(a < lo) or np.any(a > hi):
        raise ValueError(f"{name}: values must lie in [{lo}, {hi}]")
    return a


def single_quat(q, name="q") -> np.ndarray:
    """One unit quaternion of shape (4,) (ValueError naming ``name`` otherwise)."""
    q = rot.check_unit_quat(q, name)
    if q.shape != (4,):
        raise ValueError(f"{name}: expected a single quaternion of shape (4,), got {q.shape}")
    return q


def single_vec(v, name) -> np.ndarray:
    """One finite 3-vector of shape (3,) (ValueError naming ``name`` otherwise)."""
    v = vec3(v, name)
    if v.shape != (3,):
        raise ValueError(f"{name}: expected shape (3,), got {v.shape}")
    return v


def times(t, name) -> np.ndarray:
    """Non-empty, finite, non-decreasing 1-D float array of times, s (repeats allowed;
    ValueError naming ``name`` otherwise)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)):
        raise ValueError(f"{name}: expected a non-empty finite 1-D array of times (s)")
    if np.any(np.diff(t) < 0):
        raise ValueError(f"{name}: times must be non-decreasing")
    return t
