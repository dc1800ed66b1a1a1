"""Shape files: TOML facet lists, OBJ/STL meshes with a TOML material map, the shape library.

Facet-list form (``shapes/cube_1u.toml``)::

    [shape]
    name = "cube_1u"
    description = "..."
    mass_kg = 1.33
    inertia_kg_m2 = [[...], [...], [...]]   # or inertia_diag_kg_m2 = [Ixx, Iyy, Izz]
    # convex = true                         # optional; default: computed from the facets

    [materials.panel]                       # see lightcurve.photometry.materials
    brdf = "cook_torrance"
    xi = 0.5
    a = 0.3
    m = 0.2

    [[facets]]
    normal = [1.0, 0.0, 0.0]                # outward unit normal, body axes
    area_m2 = 0.01
    center_m = [0.05, 0.0, 0.0]             # centre of pressure, body axes, m
    material = "panel"
    # tangent = [0, 1, 0]                   # optional (anisotropic BRDFs)

Mesh form: the same ``[shape]`` table with ``mesh = "file.obj"`` (or .stl; relative to the
TOML file), ``scale`` (mesh units → m, default 1), ``merge_coplanar`` (default true: adjacent
coplanar triangles become one facet), ``default_material``, and optional
``[[material_map]]`` entries assigning a material to facets by ``normal`` (+ ``tol_deg``) or
by facet indices ``facets = [...]`` (indices after merging). The mesh origin is the body
origin (should be the centre of mass); without an inertia key, a watertight mesh's inertia
is computed for uniform density and the given mass.

A mesh may also be given separately: ``load_shape(("hull.obj", "hull_materials.toml"))``,
where the TOML has no ``mesh`` key.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._paths import data_dir
from ..errors import InputError
from ..io.safe_open import MESH_MAX_BYTES as _MAX_MESH_BYTES
from ..io.tomlio import Section, load_toml
from .brdf import get_brdf
from .brdf_models import perpendicular_unit
from .facets import Shape, facets_convex
from .materials import Material, material_from_section

__all__ = ["load_shape", "list_shapes", "shape_library", "validate_shape", "NONCONVEX_NOTE"]

NONCONVEX_NOTE = ("not convex: the magnitude model (Bernard eq. 5.5) sums facets independently; "
                  "self-shadowing and occlusion are not modelled for this shape")

_UNIT_TOL = 1e-6


class _Problems:
    """Collects problems (lenient mode) or raises the first error (strict mode)."""

    def __init__(self, strict: bool):
        self.strict = strict
        self.items: list[str] = []

    def error(self, exc: InputError):
        if self.strict:
            raise exc
        self.items.append(str(exc))

    def warn(self, text: str):
        self.items.append(text)


# ----------------------------------------------------------------------------------------
# library
# ----------------------------------------------------------------------------------------
def _library_dirs(library_dirs) -> list[Path]:
    dirs = []
    if library_dirs is not None:
        if isinstance(library_dirs, (str, Path)):
            library_dirs = [library_dirs]
        dirs.extend(Path(d) for d in library_dirs)
    from ..plugins import plugin_shape_dirs

    dirs.extend(plugin_shape_dirs())  # folders listed by --plugin modules (SHAPE_DIRS)
    try:
        dirs.append(data_dir("shapes"))
    except FileNotFoundError:
        pass
    return dirs


def shape_library(library_dirs=None) -> dict[str, Path]:
    """Library entries ``name -> TOML path``; user folders come first and shadow bundled names."""
    out: dict[str, Path] = {}
    for d in _library_dirs(library_dirs):
        if not d.is_dir():
            raise InputError("shape library folder not found", file=d)
        for p in sorted(d.glob("*.toml")):
            out.setdefault(p.stem, p)
    return out


def list_shapes(library_dirs=None) -> list[str]:
    """Sorted names of the shapes in the library (bundled ``shapes/`` plus ``library_dirs``)."""
    return sorted(shape_library(library_dirs))


# ----------------------------------------------------------------------------------------
# loading
# ----------------------------------------------------------------------------------------
def load_shape(spec, library_dirs=None, *, library_only: bool = False) -> Shape:
    """Load a shape.

    Parameters
    ----------
    spec : str, Path, tuple or Shape
        A library name (``"cube_1u"``), a path to a shape TOML (facet list or mesh form), or a
        tuple ``(mesh_path, materials_toml)``. A :class:`Shape` is returned unchanged.
    library_dirs : path or list of paths, optional
        Extra library folders searched before the bundled ``shapes/``.
    library_only : bool
        Accept only a library name, never a path: for names read from data files (a
        lightcurve's ``attrs["shape"]``, a scenario stored in an HDF5 file), which must not
        make the program read an arbitrary file.

    Raises
    ------
    InputError
        Unknown names, malformed TOML/OBJ/STL, unknown BRDFs, parameters out of range,
        zero-area or degenerate facets, non-unit normals — naming the file and field.
        Non-convexity is not an error (see :func:`validate_shape`).
    """
    if library_only and not isinstance(spec, Shape):
        lib = shape_library(library_dirs)
        if not isinstance(spec, str) or spec not in lib:
            raise InputError("not a shape library name (a name read from a data file may not "
                             "name a file)", field="shape", value=str(spec),
                             allowed=", ".join(sorted(lib)) or "no shapes in the library")
        spec = lib[spec]
    shape, _ = _load(spec, library_dirs, _Problems(strict=True))
    return shape


def validate_shape(shape_or_path, library_dirs=None) -> list[str]:
    """List every problem of a shape (empty list: none).

    Reports zero-area/degenerate facets, non-unit normals, materials out of range
    (ξ ∈ [0,1], a ∈ (0,1), m ∈ (0,1] and the other BRDFs' ranges), bad mass properties and
    non-convex shapes (self-shadowing is not modelled for them). Accepts what
    :func:`load_shape` accepts, or a :class:`Shape`.
    """
    if isinstance(shape_or_path, Shape):
        return _check_shape(shape_or_path)
    probs = _Problems(strict=False)
    try:
        shape, _ = _load(shape_or_path, library_dirs, probs)
    except InputError as exc:  # fatal: cannot even build the shape
        return probs.items + [str(exc)]
    if shape is not None:
        extra = [p for p in _check_shape(shape, materials=False, geometry=False)
                 if p not in probs.items]
        probs.items.extend(extra)
    return probs.items


def _resolve_spec(spec, library_dirs):
    if isinstance(spec, tuple):
        if len(spec) != 2:
            raise InputError("expected (mesh_path, materials_toml)", value=spec)
        return Path(spec[1]), Path(spec[0])
    p = Path(spec)
    if p.suffix.lower() in (".obj", ".stl"):
        raise InputError("a mesh needs a TOML material map: pass (mesh_path, materials_toml) "
                         "or a shape TOML with a 'mesh' key", file=p)
    if p.suffix.lower() == ".toml" or p.exists() or len(p.parts) > 1:
        if not p.exists():  # a FIFO or device is refused by the TOML reader, never opened
            raise InputError("shape file not found", file=p)
        return p, None
    lib = shape_library(library_dirs)
    if str(spec) not in lib:
        raise InputError("unknown shape", field="shape", value=str(spec),
                         allowed=", ".join(sorted(lib)) or "no shapes in the library")
    return lib[str(spec)], None


def _load(spec, library_dirs, probs: _Problems):
    if isinstance(spec, Shape):
        return spec, probs
    toml_path, mesh_path = _resolve_spec(spec, library_dirs)
    doc = load_toml(toml_path)
    root = Section(doc, file=toml_path)
    sh = root.section("shape")
    base = toml_path.parent
    name = sh.str("name", toml_path.stem)
    description = sh.str("description", "")
    mass = _get(probs, lambda: sh.float("mass_kg", min=0.0, min_open=True), 1.0)
    convex_decl = _get(probs, lambda: sh.bool("convex", None), None)

    # materials -------------------------------------------------------------------------
    mats_sec = root.section("materials")
    materials: dict[str, Material] = {}
    for mname in mats_sec.data:
        msec = mats_sec.section(mname)
        try:
            materials[mname] = material_from_section(msec, mname, base)
        except InputError as exc:
            fatal = (exc.field is None or exc.field.endswith((".brdf", ".table"))
                     or "unknown parameter" in exc.bare_message or "missing" in exc.bare_message
                     or msec.data.get("brdf") == "tabulated")
            if probs.strict or fatal:
                raise
            # lenient: record every out-of-range parameter, keep the raw values
            model = get_brdf(msec.data["brdf"])
            raw = {k: v for k, v in msec.data.items() if k not in ("brdf", "description")}
            found: list = []
            vals = model.resolve_params(raw, file=msec.file, field=msec.name, problems=found)
            for e in found:
                probs.error(e)
            materials[mname] = Material(mname, model, vals)
    if not materials:
        raise InputError("no materials defined", file=toml_path, field="materials")

    mesh_key = sh.str("mesh", None)
    if mesh_path is not None and mesh_key is not None:
        raise InputError("mesh given twice (argument and 'shape.mesh')", file=toml_path, field="shape.mesh")
    if mesh_key is not None:
        mesh_path = Path(mesh_key) if Path(mesh_key).is_absolute() else base / mesh_key

    tangents = None
    vertices = faces = None
    if mesh_path is None:
        areas, normals, centers, fmats, tangents = _facets_from_toml(root, materials, toml_path, probs)
        for k in ("merge_coplanar", "default_material"):
            if sh.has(k):
                raise InputError("only allowed with a mesh", file=toml_path, field=f"shape.{k}")
        mesh_inertia = None
    else:
        scale = sh.float("scale", 1.0, min=0.0, min_open=True)
        merge = sh.bool("merge_coplanar", True)
        default_mat = sh.str("default_material", None)
        (areas, normals, centers, vertices, faces, mesh_convex, mesh_inertia_unit) = \
            _facets_from_mesh(mesh_path, scale, merge, probs)
        fmats = _assign_mesh_materials(root, materials, default_mat, normals, toml_path, probs)
        if convex_decl is None:
            convex_decl = mesh_convex
        mesh_inertia = None if mesh_inertia_unit is None else mesh_inertia_unit * mass

    # mass properties -------------------------------------------------------------------
    inertia = _get(probs, lambda: _inertia(sh, toml_path, mesh_inertia), np.eye(3))
    sh.check_unknown(extra_allowed=("mesh",))
    root.raw("facets", None)
    root.raw("material_map", None)
    root.check_unknown()

    # geometry checks -------------------------------------------------------------------
    F = areas.size
    norms = np.linalg.norm(normals, axis=1)
    for i in range(F):
        where = f"facets[{i}]"
        if not areas[i] > 0.0:
            probs.error(InputError("zero-area or degenerate facet", file=toml_path if mesh_path is None
                                   else mesh_path, field=f"{where}.area_m2", value=float(areas[i]),
                                   allowed="> 0"))
        if norms[i] < 1e-12:
            probs.error(InputError("degenerate facet: zero normal", file=toml_path if mesh_path is None
                                   else mesh_path, field=f"{where}.normal"))
        elif abs(norms[i] - 1.0) > _UNIT_TOL:
            probs.error(InputError(f"normal is not a unit vector (|n| = {norms[i]:.9g})",
                                   file=toml_path, field=f"{where}.normal",
                                   value=normals[i].tolist(), allowed=f"| |n| - 1 | <= {_UNIT_TOL:g}"))
    safe = np.where(norms[:, None] > 1e-12, normals / np.where(norms > 1e-12, norms, 1.0)[:, None],
                    np.array([0.0, 0.0, 1.0]))
    shape = Shape(name, np.maximum(areas, 0.0), safe, centers, fmats, mass, inertia,
                  convex=convex_decl, tangents_body=tangents, description=description,
                  source=str(mesh_path if mesh_path is not None else toml_path),
                  vertices_m=vertices, faces=faces)
    if not shape.convex:
        probs.warn(f"{shape.source}: {NONCONVEX_NOTE}")
    return shape, probs


def _get(probs, fn, fallback):
    try:
        return fn()
    except InputError as exc:
        probs.error(exc)
        return fallback


#: largest inertia element accepted, kg·m² (the ISS, the heaviest spacecraft, has principal
#: moments of order 10⁸ kg·m²; four orders of margin; values near 1e308 overflow the
#: eigen-decomposition and the Euler equations)
MAX_INERTIA_KG_M2 = 1e12


def check_inertia_magnitude(J, file, field) -> None:
    """InputError when an inertia element exceeds :data:`MAX_INERTIA_KG_M2` in magnitude."""
    J = np.asarray(J, float)
    if not np.all(np.abs(J) <= MAX_INERTIA_KG_M2):
        raise InputError("inertia element too large", file=file, field=field,
                         value=float(np.max(np.abs(J))),
                         allowed=f"|I_ij| <= {MAX_INERTIA_KG_M2:g} kg m^2")


def _inertia(sh: Section, file, mesh_inertia):
    if sh.has("inertia_kg_m2") and sh.has("inertia_diag_kg_m2"):
        raise InputError("give either inertia_kg_m2 or inertia_diag_kg_m2, not both", file=file,
                         field="shape.inertia_kg_m2")
    if sh.has("inertia_kg_m2"):
        J = sh.matrix("inertia_kg_m2", shape=(3, 3))
        fld = "shape.inertia_kg_m2"
    elif sh.has("inertia_diag_kg_m2"):
        J = np.diag(sh.vector("inertia_diag_kg_m2", n=3))
        fld = "shape.inertia_diag_kg_m2"
    elif mesh_inertia is not None:
        return mesh_inertia
    else:
        raise InputError("missing inertia (inertia_kg_m2 or inertia_diag_kg_m2; computed "
                         "automatically only for watertight meshes)", file=file, field="shape.inertia_kg_m2")
    check_inertia_magnitude(J, file, fld)
    if not np.allclose(J, J.T, rtol=1e-9, atol=1e-12 * max(1.0, np.abs(J).max())):
        raise InputError("inertia matrix is not symmetric", file=file, field=fld, value=J.tolist())
    ev = np.linalg.eigvalsh(J)
    if ev[0] <= 0:
        raise InputError("inertia matrix is not positive definite", file=file, field=fld,
                         value=ev.tolist())
    # triangle inequality of principal moments (a physical rigid body)
    if ev[0] + ev[1] < ev[2] * (1 - 1e-9):
        raise InputError("principal moments violate the triangle inequality I1 + I2 >= I3",
                         file=file, field=fld, value=ev.tolist())
    return J


def _facets_from_toml(root: Section, materials, file, probs):
    secs = root.sections("facets", None)
    if not secs:
        raise InputError("no facets: give [[facets]] entries or shape.mesh", file=file, field="facets")
    areas, normals, centers, mats, tangs = [], [], [], [], []
    any_tangent = False
    for s in secs:
        areas.append(_get(probs, lambda: s.float("area_m2"), 0.0))
        normals.append(_get(probs, lambda: s.vector("normal", n=3), np.zeros(3)))
        centers.append(_get(probs, lambda: s.vector("center_m", n=3), np.zeros(3)))
        mname = s.str("material")
        if mname not in materials:
            raise InputError("unknown material", file=file, field=f"{s.name}.material", value=mname,
                             allowed=", ".join(materials))
        mats.append(materials[mname])
        t = _get(probs, lambda: s.vector("tangent", None, n=3), None)
        tangs.append(t)
        any_tangent = any_tangent or t is not None
        s.check_unknown()
    normals = np.array(normals)
    tangents = None
    if any_tangent:

        nn = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
        tangents = perpendicular_unit(nn)
        for i, t in enumerate(tangs):
            if t is not None:
                t = t - np.dot(t, nn[i]) * nn[i]
                if np.linalg.norm(t) < 1e-9:
                    raise InputError("tangent is parallel to the normal", file=file,
                                     field=f"facets[{i}].tangent")
                tangents[i] = t / np.linalg.norm(t)
    return np.array(areas), normals, np.array(centers), mats, tangents


def triangle_areas_normals(tri):
    """Areas (T,) m² and unit normals (T,3) of triangles ``tri`` (T,3,3) (right-handed vertex
    order); a degenerate triangle has area 0 and normal 0."""
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cr, axis=1)
    return area, cr / np.maximum(2.0 * area, 1e-300)[:, None]


def coplanar_groups(mesh, tri_area, merge=True) -> list:
    """The mesh loader's facets: index arrays of the triangles of each trimesh ``facets``
    group (coplanar neighbours; only groups without a degenerate triangle, and only when
    ``merge``), every other triangle alone, sorted by smallest triangle index."""
    groups = []
    used = np.zeros(len(tri_area), bool)
    if merge:
        for g in mesh.facets:
            g = np.asarray(g, np.int64)
            if np.all(tri_area[g] > 0):
                groups.append(g)
                used[g] = True
    groups.extend(np.array([i]) for i in np.flatnonzero(~used))
    groups.sort(key=lambda g: int(g.min()))
    return groups


def _facets_from_mesh(path: Path, scale, merge, probs):
    import trimesh

    if path.suffix.lower() not in (".obj", ".stl"):
        raise InputError("unsupported mesh format", file=path, value=path.suffix, allowed=".obj, .stl")
    import io

    from ..io.safe_open import read_bytes

    # regular file only, size from the opened descriptor; trimesh parses the bytes (no other
    # file is opened: an OBJ's mtllib is not followed)
    raw = read_bytes(path, max_bytes=_MAX_MESH_BYTES, what="mesh file")
    try:
        mesh = trimesh.load(io.BytesIO(raw), file_type=path.suffix.lower().lstrip("."),
                            force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for malformed files
        raise InputError(f"cannot read mesh: {type(exc).__name__}: {exc}", file=path) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError("mesh has no triangles (malformed or empty file)", file=path)
    V = np.asarray(mesh.vertices, float) * scale
    Fc = np.asarray(mesh.faces, np.int64)
    if not np.all(np.isfinite(V)):
        raise InputError("mesh has non-finite vertex coordinates", file=path)
    tri = V[Fc]
    tri_area, tri_norm = triangle_areas_normals(tri)
    tri_cent = tri.mean(axis=1)
    groups = coplanar_groups(mesh, tri_area, merge)
    areas = np.array([tri_area[g].sum() for g in groups])
    normals = np.array([(tri_norm[g] * tri_area[g, None]).sum(0) / max(tri_area[g].sum(), 1e-300)
                        for g in groups])
    # unit after area-weighting coplanar triangles (they share the normal); degenerate stay 0
    nn = np.linalg.norm(normals, axis=1)
    normals = np.where(nn[:, None] > 1e-12, normals / np.where(nn > 1e-12, nn, 1.0)[:, None], 0.0)
    centers = np.array([(tri_cent[g] * tri_area[g, None]).sum(0) / max(tri_area[g].sum(), 1e-300)
                        if tri_area[g].sum() > 0 else tri_cent[g].mean(0) for g in groups])
    for i in np.flatnonzero(areas <= 1e-14 * max(areas.max(), 1e-300)):
        probs.error(InputError("zero-area or degenerate triangle", file=path, field=f"facets[{i}]",
                               value=float(areas[i])))
        areas[i] = 0.0
    convex = bool(mesh.is_convex) if mesh.is_watertight else False
    inertia_unit = None
    if mesh.is_watertight and mesh.volume > 0:
        m2 = mesh.copy()
        m2.apply_scale(scale)
        inertia_unit = np.asarray(m2.moment_inertia, float) / m2.mass  # per kg
    return areas, normals, centers, V, Fc, convex, inertia_unit


def _assign_mesh_materials(root: Section, materials, default_mat, normals, file, probs):
    F = normals.shape[0]
    assigned: list = [None] * F
    if default_mat is not None:
        if default_mat not in materials:
            raise InputError("unknown material", file=file, field="shape.default_material",
                             value=default_mat, allowed=", ".join(materials))
        assigned = [materials[default_mat]] * F
    for s in root.sections("material_map", None):
        mname = s.str("material")
        if mname not in materials:
            raise InputError("unknown material", file=file, field=f"{s.name}.material", value=mname,
                             allowed=", ".join(materials))
        if s.has("normal") == s.has("facets"):
            raise InputError("give exactly one of 'normal' or 'facets'", file=file, field=s.name)
        if s.has("normal"):
            n = s.vector("normal", n=3)
            if np.linalg.norm(n) < 1e-12:
                raise InputError("zero vector", file=file, field=f"{s.name}.normal")
            n = n / np.linalg.norm(n)
            tol = np.radians(s.float("tol_deg", 1.0, min=0.0, max=180.0))
            sel = np.flatnonzero(normals @ n >= np.cos(tol) - 1e-12)
        else:
            idx = s.raw("facets")
            if not isinstance(idx, list) or not all(isinstance(i, int) and not isinstance(i, bool)
                                                    for i in idx):
                raise InputError("expected a list of facet indices", file=file,
                                 field=f"{s.name}.facets", value=idx)
            sel = np.asarray(idx, np.int64)
            if sel.size and (sel.min() < 0 or sel.max() >= F):
                raise InputError("facet index out of range", file=file, field=f"{s.name}.facets",
                                 value=idx, allowed=f"0..{F - 1}")
        s.check_unknown()
        for i in sel:
            assigned[int(i)] = materials[mname]
    missing = [i for i, m in enumerate(assigned) if m is None]
    if missing:
        raise InputError(f"{len(missing)} mesh facet(s) have no material (first: {missing[0]}); "
                         "set shape.default_material or add [[material_map]] entries",
                         file=file, field="material_map")
    return assigned


def _check_shape(shape: Shape, materials=True, geometry=True) -> list[str]:
    """Problems of an in-memory shape (same wording as the file checks)."""
    out = []
    src = shape.source or shape.name
    if geometry:
        for i in np.flatnonzero(~(shape.areas_m2 > 0)):
            out.append(f"{src}: field 'facets[{i}].area_m2': zero-area or degenerate facet")
        nn = np.linalg.norm(shape.normals_body, axis=1)
        for i in np.flatnonzero(np.abs(nn - 1) > _UNIT_TOL):
            out.append(f"{src}: field 'facets[{i}].normal': normal is not a unit vector (|n| = {nn[i]:.9g})")
    if materials:
        seen = set()
        for i, m in enumerate(shape.materials):
            if id(m) in seen:
                continue
            seen.add(id(m))
            found: list = []
            m.brdf.resolve_params(m.params, file=shape.source, field=f"materials.{m.name}",
                                  problems=found)
            out.extend(str(e) for e in found)
    if shape.mass_kg <= 0:
        out.append(f"{src}: field 'shape.mass_kg': mass must be > 0 (got {shape.mass_kg})")
    ev = np.linalg.eigvalsh(0.5 * (shape.inertia_kg_m2 + shape.inertia_kg_m2.T))
    if ev[0] <= 0:
        out.append(f"{src}: field 'shape.inertia_kg_m2': inertia is not positive definite")
    if not shape.convex and not any(NONCONVEX_NOTE in p for p in out):
        out.append(f"{src}: {NONCONVEX_NOTE}")
    if geometry and shape.convex and not facets_convex(shape.normals_body, shape.centers_body_m,
                                                       1e-9 + 1e-9 * np.abs(shape.centers_body_m).max()):
        out.append(f"{src}: declared convex but a facet centre lies in front of another facet's plane; "
                   f"{NONCONVEX_NOTE}")
    return out
