"""Tabulated (measured) BRDF interpolated from in-plane samples.

Data format (Fankhauser et al. 2023 Starlink tables, ``chassis_brdf.csv`` and
``solar_array_brdf.csv``): whitespace-separated columns ``phi_i theta_i phi_o theta_o brdf``
with ``#`` comments. Despite the letters, ``phi_*`` are the **zenith** angles and
``theta_*`` the azimuths (deg), as the file header says. All samples are in the plane of
incidence: the source at azimuth −180°, the detector at azimuth 0° with a *signed* zenith
``phi_o`` ∈ [−90°, 90°]; positive ``phi_o`` is the forward (specular) side, so the mirror
direction is ``phi_o = phi_i`` (the measured peaks sit there). Incidence zeniths are
5°, 41.4°, 60° and 75°; the BRDF is in sr⁻¹.

Interpolation model (isotropic surface; documented approximation):

* The table is re-indexed by the signed offset from the mirror direction,
  ``d = phi_o − phi_i``, so that the narrow specular spike stays aligned when interpolating
  between incidence angles. ``log f`` is interpolated linearly in ``d`` (per measured
  incidence angle) and then linearly in the incidence zenith θ_i (clamped to the measured
  5°…75°; outside the measured ``d`` range the end value is held).
* An arbitrary geometry is mapped to (θ_i, δ, β): δ = angle between ô and the mirror
  direction r̂, β = azimuth of ô around r̂ measured from the plane of incidence (β = 0: the
  forward in-plane branch ``d = +δ``; β = π: the backward branch ``d = −δ``). The value is
  the blend ``cos²(β/2) f(θ_i, +δ) + sin²(β/2) f(θ_i, −δ)``, which reproduces every in-plane
  sample exactly and is continuous everywhere.
* Reciprocity is not imposed (four incidence angles are too few to use it to fill the
  table). The measured tables are only roughly reciprocal: on the swapped pairs the grid
  allows (e.g. θ_i = 5°, φ_o = 60° vs θ_i = 60°, φ_o = 5°) they agree to within about 20 %
  (chassis) and 50 % (solar array).

The specular spike of these tables is a single 1° sample wide, so it is not resolvable by
any interpolation: held-out errors quoted in the tests exclude |d| ≤ 1°.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.safe_open import BRDF_MAX_BYTES as _MAX_TABLE_BYTES
from .brdf import BRDF
from .brdf_models import perpendicular_unit

__all__ = ["TabulatedBRDF", "load_brdf_table"]

_FLOOR = 1e-12  # sr⁻¹, floor before taking logs


def load_brdf_table(path):
    """Read a BRDF table file; returns (theta_i_deg, phi_o_deg, brdf_sr) 1-D arrays.

    Raises :class:`InputError` naming the file and line for malformed content, azimuths
    that are not in-plane (source −180°/180°, detector 0°), or non-positive/non-finite values.
    """
    from ..io.safe_open import read_bytes

    path = Path(path)
    # a regular file of at most 64 MiB (size from the opened descriptor), refused before reading
    raw = read_bytes(path, max_bytes=_MAX_TABLE_BYTES, what="BRDF table")
    rows = []
    for lineno, line in enumerate(raw.decode("utf-8", errors="replace").splitlines(), 1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        parts = text.replace(",", " ").split()
        if len(parts) != 5:
            raise InputError("expected 5 columns: phi_i theta_i phi_o theta_o brdf", file=path,
                             field=f"line {lineno}", value=line.strip())
        try:
            vals = [float(x) for x in parts]
        except ValueError:
            raise InputError("not a number", file=path, field=f"line {lineno}",
                             value=line.strip()) from None
        if not np.all(np.isfinite(vals)):
            raise InputError("non-finite value", file=path, field=f"line {lineno}", value=line.strip())
        zi, ai, zo, ao, f = vals
        if not (0.0 <= zi < 90.0):
            raise InputError("incidence zenith out of range", file=path, field=f"line {lineno}",
                             value=zi, allowed="[0, 90) deg")
        if not (-90.0 <= zo <= 90.0):
            raise InputError("signed scattering zenith out of range", file=path,
                             field=f"line {lineno}", value=zo, allowed="[-90, 90] deg")
        if abs(abs(ai) - 180.0) > 1e-9 or abs(ao) > 1e-9:
            raise InputError("only in-plane tables are supported (theta_i = -180, theta_o = 0)",
                             file=path, field=f"line {lineno}", value=(ai, ao))
        if f < 0.0:
            raise InputError("negative BRDF value", file=path, field=f"line {lineno}", value=f)
        rows.append((zi, zo, f))
    if len(rows) < 4:
        raise InputError("too few samples in BRDF table", file=path, value=len(rows), allowed=">= 4")
    a = np.asarray(rows)
    return a[:, 0], a[:, 1], a[:, 2]


class TabulatedBRDF(BRDF):
    """Measured in-plane BRDF, interpolated as described in the module docstring.

    Parameters
    ----------
    theta_i_deg, phi_o_deg, values : 1-D arrays
        Incidence zenith (deg), signed in-plane scattering zenith (deg, + = forward side),
        BRDF (sr⁻¹). At least two samples per incidence angle.
    name : str
        Label (e.g. the file name).

    The only material parameter is ``scale`` (≥ 0, default 1), a multiplier on the table.
    """

    param_names = ("scale",)
    param_bounds = {"scale": (0.0, None, False, False)}
    defaults = {"scale": 1.0}
    kernel_id = None

    def __init__(self, theta_i_deg, phi_o_deg, values, name: str = "tabulated"):
        ti = np.asarray(theta_i_deg, float)
        po = np.asarray(phi_o_deg, float)
        v = np.asarray(values, float)
        if not (ti.shape == po.shape == v.shape and ti.ndim == 1):
            raise ValueError("theta_i_deg, phi_o_deg, values must be 1-D arrays of equal length")
        self.name = name
        self.incidences_deg = np.unique(ti)
        self._d = []
        self._logf = []
        for t in self.incidences_deg:
            m = ti == t
            d = po[m] - t
            order = np.argsort(d)
            d = d[order]
            lf = np.log(np.maximum(v[m][order], _FLOOR))
            if d.size < 2:
                raise ValueError(f"incidence {t} deg has fewer than 2 samples")
            self._d.append(d)
            self._logf.append(lf)

    @classmethod
    def from_csv(cls, path, name: str | None = None) -> "TabulatedBRDF":
        """Build from a table file (format in the module docstring)."""
        ti, po, f = load_brdf_table(path)
        try:
            return cls(ti, po, f, name=name or f"tabulated:{Path(path).name}")
        except ValueError as exc:  # e.g. an incidence angle with a single sample
            raise InputError(str(exc), file=path, allowed=">= 2 samples per incidence angle") from None

    # -- in-plane lookup -------------------------------------------------------------------
    def in_plane(self, theta_i_deg, d_deg) -> np.ndarray:
        """Interpolated BRDF (sr⁻¹) at incidence zenith θ_i and signed mirror offset d (deg)."""
        ti = np.clip(np.asarray(theta_i_deg, float), self.incidences_deg[0], self.incidences_deg[-1])
        d = np.asarray(d_deg, float)
        ti, d = np.broadcast_arrays(ti, d)
        grid = self.incidences_deg
        if grid.size == 1:
            return np.exp(np.interp(d, self._d[0], self._logf[0]))
        k = np.clip(np.searchsorted(grid, ti, side="right") - 1, 0, grid.size - 2)
        w = (ti - grid[k]) / (grid[k + 1] - grid[k])
        lo = np.empty(d.shape)
        hi = np.empty(d.shape)
        for j in range(grid.size - 1):
            m = k == j
            if np.any(m):
                lo[m] = np.interp(d[m], self._d[j], self._logf[j])
                hi[m] = np.interp(d[m], self._d[j + 1], self._logf[j + 1])
        return np.exp((1.0 - w) * lo + w * hi)

    # -- general geometry ------------------------------------------------------------------
    def evaluate(self, n, s, o, params: dict):
        """f_r (sr⁻¹) for unit n, s (object→Sun), o (object→observer) in one frame (...,3)."""

        n, s, o = np.broadcast_arrays(np.asarray(n, float), np.asarray(s, float),
                                      np.asarray(o, float))
        scale = np.asarray(params.get("scale", 1.0), float)
        ns = np.einsum("...k,...k->...", n, s)
        no = np.einsum("...k,...k->...", n, o)
        cos_i = np.clip(ns, -1.0, 1.0)
        theta_i = np.degrees(np.arccos(cos_i))
        # x̂: horizontal direction of the mirror ray = −(projection of ŝ on the facet plane)
        t = -(s - ns[..., None] * n)
        tn = np.linalg.norm(t, axis=-1, keepdims=True)
        perp = perpendicular_unit(n)
        x = np.where(tn > 1e-12, t / np.where(tn > 1e-12, tn, 1.0), perp)
        sin_i = np.sqrt(np.maximum(0.0, 1.0 - cos_i ** 2))
        r = sin_i[..., None] * x + cos_i[..., None] * n          # mirror direction
        e1 = cos_i[..., None] * x - sin_i[..., None] * n         # ∂r/∂θ_i: forward in-plane
        y = np.cross(n, x)
        ro = np.clip(np.einsum("...k,...k->...", r, o), -1.0, 1.0)
        delta = np.degrees(np.arccos(ro))
        w = o - ro[..., None] * r
        beta = np.arctan2(np.einsum("...k,...k->...", w, y), np.einsum("...k,...k->...", w, e1))
        wf = 0.5 * (1.0 + np.cos(beta))                            # cos²(β/2)
        f = wf * self.in_plane(theta_i, delta) + (1.0 - wf) * self.in_plane(theta_i, -delta)
        return np.where((ns > 0) & (no > 0), scale * f, 0.0)
