"""The faceted shape model: facets (area, normal, centre of pressure, material), mass, inertia.

Frames and units: every vector is in **body axes**; areas in m², lengths in m, mass in kg,
inertia in kg m² about the centre of mass in body axes. Normals are outward unit vectors.

The magnitude model (Bernard eq. 5.2–5.6) sums facets independently, which is exact only for
convex objects: :attr:`Shape.convex` records whether that holds; self-shadowing and mutual
occlusion are *not* modelled for non-convex shapes.
"""

from __future__ import annotations

import numpy as np

from .brdf import PARAM_COLUMNS
from .brdf_models import perpendicular_unit
from .materials import Material

__all__ = ["Shape", "facets_convex"]


def facets_convex(normals, centers, tol_m: float = 1e-9) -> bool:
    """True when every facet centre lies on or behind every other facet's plane.

    ``n_i · (c_j − c_i) ≤ tol`` for all i ≠ j (body frame, metres) — the condition under
    which no facet can occlude or shadow another for a closed convex polyhedron. For an
    open facet list (e.g. a two-plate satellite) it is the centre-point approximation of
    the same condition.

    Evaluated in blocks of rows (at most about 4·10⁶ pairs, 96 MB, at a time) so that the
    F×F×3 differences of a large mesh are never held at once; stops at the first violation.
    """
    n = np.asarray(normals, float)
    c = np.asarray(centers, float)
    F = n.shape[0]
    if F < 2:
        return True
    rows = max(1, 4_000_000 // F)
    for i0 in range(0, F, rows):
        i1 = min(F, i0 + rows)
        d = np.einsum("ik,ijk->ij", n[i0:i1], c[None, :, :] - c[i0:i1, None, :])
        d[np.arange(i1 - i0), np.arange(i0, i1)] = -np.inf
        if not np.all(d <= tol_m):
            return False
    return True


class Shape:
    """A faceted object.

    Parameters
    ----------
    name : str
    areas_m2 : (F,) facet areas, m², > 0
    normals_body : (F,3) outward unit normals, body axes (checked to 1e-6)
    centers_body_m : (F,3) facet centres of pressure, body axes, m (relative to the centre of mass)
    materials : sequence of F :class:`Material` (one per facet; may repeat objects)
    mass_kg : float > 0
    inertia_kg_m2 : (3,3) symmetric positive-definite inertia about the centre of mass, body axes
    convex : bool or None
        None -> computed with :func:`facets_convex`.
    tangents_body : (F,3) optional unit tangents (anisotropic BRDFs); default perpendicular to n.
    description, source : str, optional
    vertices_m, faces : optional mesh arrays kept for plotting and validation.

    Attributes (besides the above)
    ------------------------------
    brdf_names : (F,) object array of BRDF names
    model_ids : (F,) int64 numba kernel id per facet (−1: evaluated in numpy)
    params : (F, 7) float64 packed kernel parameters (see :mod:`lightcurve.core.photometry`)
    param_table : dict name -> (F,) float array, NaN where the facet's BRDF lacks the parameter
    """

    def __init__(self, name, areas_m2, normals_body, centers_body_m, materials, mass_kg,
                 inertia_kg_m2, convex=None, tangents_body=None, description: str = "",
                 source=None, vertices_m=None, faces=None):

        self.name = str(name)
        self.areas_m2 = np.ascontiguousarray(areas_m2, dtype=float).reshape(-1)
        F = self.areas_m2.size
        self.normals_body = np.ascontiguousarray(normals_body, dtype=float).reshape(F, 3)
        self.centers_body_m = np.ascontiguousarray(centers_body_m, dtype=float).reshape(F, 3)
        if F == 0:
            raise ValueError("a shape needs at least one facet")
        if not np.allclose(np.linalg.norm(self.normals_body, axis=1), 1.0, atol=1e-6):
            raise ValueError("normals_body must be unit vectors (to 1e-6)")
        if np.any(self.areas_m2 < 0) or not np.all(np.isfinite(self.areas_m2)):
            raise ValueError("areas_m2 must be finite and >= 0")
        materials = tuple(materials)
        if len(materials) != F or not all(isinstance(m, Material) for m in materials):
            raise ValueError(f"need {F} Material objects, one per facet")
        self.materials = materials
        self.mass_kg = float(mass_kg)
        self.inertia_kg_m2 = np.asarray(inertia_kg_m2, dtype=float).reshape(3, 3)
        if tangents_body is None:
            tangents_body = perpendicular_unit(self.normals_body)
        self.tangents_body = np.ascontiguousarray(tangents_body, dtype=float).reshape(F, 3)
        self.convex = facets_convex(self.normals_body, self.centers_body_m) if convex is None else bool(convex)
        self.description = description
        self.source = None if source is None else str(source)
        self.vertices_m = None if vertices_m is None else np.asarray(vertices_m, float)
        self.faces = None if faces is None else np.asarray(faces, np.int64)
        self.brdf_names = np.array([m.brdf_name for m in materials], dtype=object)
        names = []
        for m in materials:
            for p in m.brdf.param_names:
                if p not in names:
                    names.append(p)
        self.param_table = {p: np.array([m.params.get(p, np.nan) for m in materials]) for p in names}
        self._repack()

    # ------------------------------------------------------------------------------------
    def _repack(self) -> None:
        F = self.n_facets
        self.model_ids = np.full(F, -1, dtype=np.int64)
        self.params = np.zeros((F, PARAM_COLUMNS))
        for i, m in enumerate(self.materials):
            kid = m.brdf.kernel_id
            if kid is None:
                continue
            self.model_ids[i] = kid
            for j, p in enumerate(m.brdf.param_names):
                self.params[i, j] = self.param_table[p][i]
            if kid == 3:  # Ashikhmin–Shirley: tangent in columns 4..6
                self.params[i, 4:7] = self.tangents_body[i]
        # numpy-evaluated groups: BRDF instance -> facet indices
        groups: dict = {}
        for i, m in enumerate(self.materials):
            if m.brdf.kernel_id is None:
                groups.setdefault(id(m.brdf), (m.brdf, []))[1].append(i)
        self.numpy_groups = [(b, np.asarray(ix, dtype=np.int64)) for b, ix in groups.values()]

    @property
    def n_facets(self) -> int:
        """Number of facets F."""
        return self.areas_m2.size

    @property
    def all_kernel(self) -> bool:
        """True when every facet's BRDF has a numba kernel."""
        return bool(np.all(self.model_ids >= 0))

    def facet_params(self, name: str) -> np.ndarray:
        """(F,) values of BRDF parameter ``name`` (NaN where the facet's model lacks it)."""
        if name not in self.param_table:
            raise KeyError(f"no facet of shape {self.name!r} has parameter {name!r}; "
                           f"known: {', '.join(self.param_table)}")
        return self.param_table[name].copy()

    def kernel_arrays(self):
        """(normals (F,3), areas (F,), model_ids (F,), params (F,7)) for the numba kernels."""
        return self.normals_body, self.areas_m2, self.model_ids, self.params

    def copy_with(self, *, name=None, areas_m2=None, mass_kg=None, inertia_kg_m2=None,
                  check: bool = True, **brdf_params) -> "Shape":
        """A copy with replaced areas, mass properties and/or per-facet reflection parameters.

        ``brdf_params``: parameter name (``xi``, ``a``, ``m``, ``Kd``…) -> scalar or (F,)
        array; applied to the facets whose BRDF has that parameter (entries of other facets
        must be NaN when an array is given). ``check=True`` validates ranges (InputError);
        ``check=False`` accepts any finite value (for filters that perturb parameters).
        """
        new = object.__new__(Shape)
        new.__dict__.update(self.__dict__)
        new.name = self.name if name is None else str(name)
        if areas_m2 is not None:
            a = np.broadcast_to(np.asarray(areas_m2, float), (self.n_facets,)).copy()
            if check and (np.any(a < 0) or not np.all(np.isfinite(a))):
                raise ValueError("areas_m2 must be finite and >= 0")
            new.areas_m2 = np.ascontiguousarray(a)
        if mass_kg is not None:
            new.mass_kg = float(mass_kg)
        if inertia_kg_m2 is not None:
            new.inertia_kg_m2 = np.asarray(inertia_kg_m2, float).reshape(3, 3)
        if brdf_params:
            table = {k: v.copy() for k, v in self.param_table.items()}
            for p, val in brdf_params.items():
                if p not in table:
                    raise KeyError(f"no facet of shape {self.name!r} has BRDF parameter {p!r}; "
                                   f"known: {', '.join(table)}")
                has = ~np.isnan(self.param_table[p])
                v = np.broadcast_to(np.asarray(val, float), (self.n_facets,)).copy()
                if np.any(~np.isnan(v[~has])) and np.ndim(val) > 0:
                    raise ValueError(f"parameter {p!r} given for facets whose BRDF lacks it")
                table[p][has] = v[has]
            new.param_table = table
            if check:
                mats = []
                for i, m in enumerate(self.materials):
                    vals = {q: table[q][i] for q in m.brdf.param_names}
                    if vals != m.params:
                        m = Material(m.name, m.brdf, m.brdf.resolve_params(
                            vals, field=f"facet[{i}] material {m.name}"))
                    mats.append(m)
                new.materials = tuple(mats)
            else:
                mats = []
                for i, m in enumerate(self.materials):
                    vals = {q: float(table[q][i]) for q in m.brdf.param_names}
                    mats.append(m if vals == m.params else Material(m.name, m.brdf, vals))
                new.materials = tuple(mats)
            new._repack()
        return new

    def __repr__(self):
        return (f"<Shape {self.name!r}: {self.n_facets} facets, {self.areas_m2.sum():.4g} m², "
                f"{self.mass_kg:g} kg, convex={self.convex}>")

    def summary(self) -> str:
        """Multi-line human-readable description (used by ``lightcurve shapes show``)."""
        lines = [f"shape {self.name}: {self.n_facets} facets, total area {self.areas_m2.sum():.6g} m², "
                 f"mass {self.mass_kg:g} kg, convex: {'yes' if self.convex else 'no (self-shadowing not modelled)'}"]
        if self.description:
            lines.append(f"  {self.description}")
        if self.source:
            lines.append(f"  source: {self.source}")
        I = self.inertia_kg_m2.copy()
        I[np.abs(I) < 1e-12 * max(np.abs(I).max(), 1e-300)] = 0.0
        I += 0.0  # no negative zeros in the printout
        lines.append("  inertia [kg m^2]: " + "; ".join(" ".join(f"{x:.6g}" for x in row) for row in I))
        mats = {}
        for i, m in enumerate(self.materials):
            mats.setdefault((m.name, m.brdf_name, tuple(sorted(m.params.items()))), []).append(i)
        lines.append("  materials:")
        for (mn, bn, ps), idx in mats.items():
            lines.append(f"    {mn} ({bn}; " + ", ".join(f"{k}={v:g}" for k, v in ps)
                         + f"): {len(idx)} facet(s)")
        if self.n_facets <= 40:
            lines.append("  facets (normal | area m^2 | centre m | material):")
            for i in range(self.n_facets):
                n = self.normals_body[i]
                c = self.centers_body_m[i]
                lines.append(f"    {i:3d}  [{n[0]:+.4f} {n[1]:+.4f} {n[2]:+.4f}]  {self.areas_m2[i]:.6g}  "
                             f"[{c[0]:+.4g} {c[1]:+.4g} {c[2]:+.4g}]  {self.materials[i].name}")
        return "\n".join(lines)
