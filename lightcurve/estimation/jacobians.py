"""Numerical Jacobians for measurement and dynamics models: complex step and central differences.

* Complex step (Squire & Trapp 1998; Martins, Sturdza & Alonso 2003):
  ``∂f/∂xⱼ = Im f(x + i h eⱼ) / h`` — no subtractive cancellation, so ``h = 1e-20`` gives
  derivatives accurate to machine precision. ``f`` must be written with complex-safe
  operations (no ``abs``, ``max``, comparisons on the perturbed quantity, ``np.real``).
* Central differences ``(f(x + h eⱼ) − f(x − h eⱼ)) / 2h`` as the independent check used by
  the tests (DESIGN.md: "finite differences for every analytic Jacobian").
"""

from __future__ import annotations

import numpy as np

__all__ = ["complex_step_jacobian", "central_difference_jacobian"]


def _x(x):
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or x.shape[0] == 0:
        raise ValueError(f"x must be a non-empty 1-D array, got shape {x.shape}")
    return x


def complex_step_jacobian(f, x, h=1e-20):
    """Jacobian (m, n) of ``f: R^n → R^m`` at ``x`` by the complex step.

    ``f`` receives a complex (n,) array and must return a complex (m,) (or scalar) array.
    """
    x = _x(x)
    if not h > 0.0:
        raise ValueError(f"step h must be > 0, got {h}")
    n = x.shape[0]
    cols = []
    for j in range(n):
        xc = x.astype(complex)
        xc[j] += 1j * h
        cols.append(np.atleast_1d(np.asarray(f(xc))).imag / h)
    return np.stack(cols, axis=-1)


def central_difference_jacobian(f, x, h=1e-6):
    """Jacobian (m, n) of ``f: R^n → R^m`` at ``x`` by central differences with step ``h``.

    ``h`` may be a scalar or an (n,) array of per-component steps (in the units of x).
    """
    x = _x(x)
    n = x.shape[0]
    hh = np.broadcast_to(np.asarray(h, dtype=float), (n,))
    if np.any(~(hh > 0.0)):
        raise ValueError("steps h must be > 0")
    cols = []
    for j in range(n):
        xp = x.copy()
        xm = x.copy()
        xp[j] += hh[j]
        xm[j] -= hh[j]
        cols.append((np.atleast_1d(np.asarray(f(xp), dtype=float))
                     - np.atleast_1d(np.asarray(f(xm), dtype=float))) / (2.0 * hh[j]))
    return np.stack(cols, axis=-1)
