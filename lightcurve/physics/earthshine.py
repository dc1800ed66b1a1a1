"""Earthshine: sunlight reflected by the Earth onto the object's facets.

The Earth is a grid of Lambertian cells (albedo map, :mod:`lightcurve.earth.albedo`). Cell j,
sunlit and in view of the object, irradiates the object from the direction ĉ_j (object →
cell) with, in units of the solar irradiance at the object (O'Keefe 2015, eq. 2.15),

    a_j = ρ_j A_j (n̂_j·ŝ)(n̂_j·û_j) / (π d_j²)

and facet i reflects a fraction of it towards the observer exactly as it reflects sunlight:

    F_earth = s Σ_j a_j Σ_i A_i max(n̂_i·ĉ_j,0) max(n̂_i·ô,0) f_r,i(ĉ_j, ô)    [m² sr⁻¹]

added to the solar flux factor of the magnitude equation (:mod:`.context`), *not* multiplied
by the object's lit fraction (an object in the Earth's shadow can still see sunlit ground).
``s`` (``albedo_scale``) scales the whole map. Cells are Earth-fixed (WGS84); ECI → Earth
fixed uses the Greenwich sidereal angle (:func:`lightcurve.earth.albedo.earth_rotation_angle`).
The facet sum ignores self-shadowing of Earthshine. Map: ``albedo = "builtin"`` (the zonal
CERES fit on a ``resolution_deg`` grid) or a CERES CSV / TOMS .dat path (relative paths
against the scenario file).

For a uniform Lambert sphere of albedo ρ seen at full phase from far away the irradiance is
(2/3) ρ (R⊕/r)² of the solar one (the Lambert sphere's geometric albedo is 2ρ/3): ≈ 0.08 at
LEO heights of 500 km for ρ = 0.3 with the finite-distance view factor — comparable to a
facet's own sunlight when it faces the Earth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .registry import Effect, ParamSpec, Prior, register_effect

__all__ = ["Earthshine", "earthshine_cells", "load_grid"]

_GRIDS: dict = {}


def load_grid(albedo: str = "builtin", resolution_deg: float = 10.0):
    """The :class:`~lightcurve.earth.albedo.AlbedoGrid` for ``albedo`` ("builtin" or a path), cached."""
    from ..earth.albedo import builtin_albedo_map, load_albedo_map

    key = (str(albedo), float(resolution_deg))
    if key not in _GRIDS:
        amap = builtin_albedo_map(resolution_deg) if albedo == "builtin" else load_albedo_map(albedo)
        _GRIDS[key] = amap.grid()
    return _GRIDS[key]


def earthshine_cells(grid, r_obj_eci_m, sun_eci_m, theta_rad):
    """Sunlit cells in view of one object position.

    Parameters: ``grid`` AlbedoGrid (Earth-fixed); ``r_obj_eci_m`` (3,) GCRS m; ``sun_eci_m``
    (3,) geocentric Sun position or direction, GCRS; ``theta_rad`` Greenwich angle.
    Returns ``(dirs_eci (M,3) unit object→cell, ratio (M,))`` (irradiance / solar irradiance).
    """
    from ..earth.albedo import albedo_cells_nb
    from .context import rotate_z

    r_e = rotate_z(np.asarray(r_obj_eci_m, float)[None], -theta_rad)[0]
    s = np.asarray(sun_eci_m, float)
    s_e = rotate_z((s / np.linalg.norm(s))[None], -theta_rad)[0]
    dirs, ratio = albedo_cells_nb(grid.centers_m, grid.normals, grid.rho_area_m2, r_e, s_e)
    keep = ratio > 0
    return rotate_z(dirs[keep], theta_rad), ratio[keep]


@register_effect
class Earthshine(Effect):
    """Earthshine: sunlight reflected by the Earth's clouds, land and sea lights up the side of the
    object facing the Earth, making it brighter than sunlight alone would, most of all when that
    side faces the observer."""

    name = "earthshine"
    params = (ParamSpec("albedo_scale", "1", 1.0, Prior("uniform", 0.7, 1.3), min=0.0, max=5.0, null=0.0,
                        description="multiplier of the albedo map"),)
    options = {"albedo": "builtin", "resolution_deg": 10.0}
    file_options = ("albedo",)  # a CERES/TOMS map path
    group = "reflection"

    def parse_options(self, sec):
        alb = sec.str("albedo", "builtin")
        if alb != "builtin":
            p = Path(alb)
            if not p.is_absolute() and sec.file and not str(sec.file).startswith("<"):
                p = Path(str(sec.file)).parent / p
            if not p.is_file():
                raise InputError("albedo map file not found", file=sec.file,
                                 field=f"{sec.name}.albedo", value=alb,
                                 allowed='"builtin" or a CERES CSV / TOMS .dat path')
            alb = str(p)
        res = sec.float("resolution_deg", 10.0, min=1.0, max=30.0)
        if abs(180.0 / res - round(180.0 / res)) > 1e-9:
            raise InputError("resolution must divide 180", file=sec.file,
                             field=f"{sec.name}.resolution_deg", value=res, allowed="1, 2, 5, 10, 15, 30 ...")
        return {"albedo": alb, "resolution_deg": res}

    def grid(self):
        return load_grid(self.opts["albedo"], self.opts["resolution_deg"])

    def flux(self, ctx, st, scale: float = 1.0) -> np.ndarray:
        """Earthshine flux factor (N,), m² sr⁻¹ in units of the solar irradiance."""
        from ..earth.albedo import earth_rotation_angle
        from ..photometry.magnitude import flux_factor
        from ..rotations import quat_rotate

        grid = self.grid()
        theta = earth_rotation_angle(ctx.epoch_utc, ctx.t + st.dt_obj)
        out = np.zeros(len(ctx))
        for i in range(len(ctx)):
            dirs, ratio = earthshine_cells(grid, st.r_obj[i], st.r_sun[i], theta[i])
            if ratio.size == 0:
                continue
            sb = quat_rotate(st.q[i], dirs)                                # (M,3) body
            ob = np.broadcast_to(quat_rotate(st.q[i], st.o_unit[i]), sb.shape)
            f = flux_factor(ctx.shape, np.ascontiguousarray(sb[None]), np.ascontiguousarray(ob[None]))[0]
            out[i] = float(np.dot(f, ratio))
        return scale * out

    def transform(self, ctx, params):
        s = float(params["albedo_scale"])
        return ctx.with_state(extra_flux=ctx.extra_flux + (lambda c, st: self.flux(c, st, s),))
