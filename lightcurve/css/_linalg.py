"""Small dense linear algebra for the CSS numba kernels (no LAPACK: fast to compile).

Matrices here are at most the number of sensors on a side (≤ ~20), so Gauss-Jordan
elimination with partial pivoting is both accurate and cheap.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["inv_nb"]


@numba.njit(cache=True)
def inv_nb(A):
    """Inverse of a square matrix by Gauss-Jordan elimination with partial pivoting.

    Returns ``(A⁻¹, ok)``; ``ok`` is False (and the first output undefined) when a pivot is
    below 1e-14 times the largest absolute entry of A (numerically singular)."""
    n = A.shape[0]
    M = A.copy()
    X = np.eye(n)
    scale = 0.0
    for i in range(n):
        for j in range(n):
            if abs(M[i, j]) > scale:
                scale = abs(M[i, j])
    if scale == 0.0:
        return X, False
    for c in range(n):
        p = c
        best = abs(M[c, c])
        for r in range(c + 1, n):
            if abs(M[r, c]) > best:
                best = abs(M[r, c])
                p = r
        if best <= 1e-14 * scale:
            return X, False
        if p != c:
            for j in range(n):
                tmp = M[c, j]
                M[c, j] = M[p, j]
                M[p, j] = tmp
                tmp = X[c, j]
                X[c, j] = X[p, j]
                X[p, j] = tmp
        piv = M[c, c]
        for j in range(n):
            M[c, j] /= piv
            X[c, j] /= piv
        for r in range(n):
            if r != c:
                f = M[r, c]
                if f != 0.0:
                    for j in range(n):
                        M[r, j] -= f * M[c, j]
                        X[r, j] -= f * X[c, j]
    return X, True
