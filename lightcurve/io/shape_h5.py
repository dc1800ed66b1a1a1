"""A resolved :class:`~lightcurve.photometry.Shape` stored inside an HDF5 file.

Lightcurve files carry the shape that produced (or models) them, so that every later command
works without the library folder the shape came from (docs/formats.md, "The shape group").
Layout of the group (default name ``shape``; F facets, M materials):

* attributes ``name``, ``description``, ``source``, ``mass_kg`` (kg), ``convex`` (0/1);
* ``areas_m2`` (F,) m²; ``normals_body`` (F, 3) outward unit normals, body axes;
  ``centers_body_m`` (F, 3) m; ``tangents_body`` (F, 3) unit tangents; ``material`` (F,) int
  index into the materials; ``inertia_kg_m2`` (3, 3) kg m² about the centre of mass;
* ``materials/<k>`` (k = 0 … M−1) groups with attributes ``name``, ``brdf`` (registry name) and
  ``params_json`` (the validated parameter values); a tabulated (measured) BRDF also stores its
  samples ``theta_i_deg``, ``phi_o_deg``, ``brdf_sr`` (see :mod:`lightcurve.photometry.tabulated`);
* optional ``mesh/vertices_m`` (V, 3) m and ``mesh/faces`` (T, 3) int (plots, self-shadowing).

Reading validates everything the shape loaders validate (unit normals, finite non-negative
areas, BRDF names and parameter ranges, a symmetric positive-definite inertia, a positive mass)
and caps the sizes before reading (:data:`MAX_FACETS`, :data:`MAX_MESH_VERTICES`), raising
:class:`~lightcurve.errors.InputError` naming the file and the dataset.
"""

from __future__ import annotations

import json

import numpy as np

from ..errors import InputError

__all__ = ["write_shape", "read_shape", "MAX_FACETS", "MAX_MESH_VERTICES"]

#: most facets a stored shape may declare (a 10⁶-facet mesh is far beyond any RSO model)
MAX_FACETS = 1_000_000
#: most mesh vertices / triangles a stored shape may declare
MAX_MESH_VERTICES = 5_000_000
_MAX_MATERIALS = 10_000
_MAX_TABLE = 1_000_000


def write_shape(h5group, shape) -> None:
    """Write ``shape`` into an (empty) h5py group (layout in the module docstring)."""
    g = h5group
    g.attrs["name"] = str(shape.name)
    g.attrs["description"] = str(getattr(shape, "description", "") or "")
    g.attrs["source"] = str(getattr(shape, "source", "") or "")
    g.attrs["mass_kg"] = float(shape.mass_kg)
    g.attrs["convex"] = int(bool(shape.convex))
    g["areas_m2"] = np.asarray(shape.areas_m2, float)
    g["normals_body"] = np.asarray(shape.normals_body, float)
    g["centers_body_m"] = np.asarray(shape.centers_body_m, float)
    g["tangents_body"] = np.asarray(shape.tangents_body, float)
    g["inertia_kg_m2"] = np.asarray(shape.inertia_kg_m2, float)
    mats, index = [], []
    for m in shape.materials:
        for k, other in enumerate(mats):
            if other is m or (other.name == m.name and other.brdf is m.brdf
                              and other.params == m.params):
                index.append(k)
                break
        else:
            index.append(len(mats))
            mats.append(m)
    g["material"] = np.asarray(index, np.int32)
    mg = g.create_group("materials")
    for k, m in enumerate(mats):
        s = mg.create_group(str(k))
        s.attrs["name"] = str(m.name)
        s.attrs["brdf"] = str(m.brdf_name)
        s.attrs["params_json"] = json.dumps({p: float(v) for p, v in m.params.items()})
        table = _table_samples(m.brdf)
        if table is not None:
            s["theta_i_deg"], s["phi_o_deg"], s["brdf_sr"] = table
    if getattr(shape, "vertices_m", None) is not None and getattr(shape, "faces", None) is not None:
        mesh = g.create_group("mesh")
        mesh["vertices_m"] = np.asarray(shape.vertices_m, float)
        mesh["faces"] = np.asarray(shape.faces, np.int64)


def _table_samples(brdf):
    """(theta_i_deg, phi_o_deg, brdf_sr) of a tabulated BRDF, None for any other model."""
    from ..photometry.tabulated import TabulatedBRDF

    if not isinstance(brdf, TabulatedBRDF):
        return None
    ti, po, f = [], [], []
    for t, d, lf in zip(brdf.incidences_deg, brdf._d, brdf._logf):
        ti.append(np.full(d.size, t))
        po.append(d + t)
        f.append(np.exp(lf))
    return np.concatenate(ti), np.concatenate(po), np.concatenate(f)


def _text(v) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def read_shape(h5group, file=None, *, prefix: str = "shape"):
    """Rebuild the :class:`~lightcurve.photometry.Shape` stored by :func:`write_shape`.

    ``file`` and ``prefix`` only name the source in error messages.

    Raises
    ------
    InputError
        Missing or mis-shaped datasets, sizes above the caps, unknown BRDFs, parameters out of
        range, non-unit normals, a bad inertia or mass.
    """
    import h5py

    from ..photometry.facets import Shape
    from ..photometry.materials import Material
    from ..photometry.shapes_io import check_inertia_magnitude

    g = h5group

    def err(field, msg, value=None, allowed=None):
        return InputError(msg, file=file, field=f"{prefix}/{field}" if field else prefix,
                          value=value, allowed=allowed)

    def ds(name, shape=None, dtype=float, cap=None, parent=g, label=None):
        label = label or name
        if name not in parent or not isinstance(parent[name], h5py.Dataset):
            raise err(label, "missing dataset")
        d = parent[name]
        if cap is not None and d.size > cap:
            raise err(label, "dataset too large", value=d.shape, allowed=f"<= {cap} elements")
        try:
            v = np.asarray(d[()], dtype=dtype)
        except (OSError, RuntimeError, ValueError, TypeError) as exc:
            raise err(label, f"cannot read dataset: {exc}") from None
        if shape is not None and v.shape != shape:
            raise err(label, f"expected shape {shape}, got {v.shape}")
        if dtype is float and not np.all(np.isfinite(v)):
            raise err(label, "contains NaN or infinite values")
        return v

    areas = ds("areas_m2", cap=MAX_FACETS)
    if areas.ndim != 1 or areas.size == 0:
        raise err("areas_m2", "expected a non-empty 1-D array", value=areas.shape)
    F = areas.size
    normals = ds("normals_body", (F, 3), cap=3 * MAX_FACETS)
    centers = ds("centers_body_m", (F, 3), cap=3 * MAX_FACETS)
    tangents = ds("tangents_body", (F, 3), cap=3 * MAX_FACETS) if "tangents_body" in g else None
    inertia = ds("inertia_kg_m2", (3, 3))
    index = ds("material", (F,), dtype=np.int64, cap=MAX_FACETS)
    if np.any(areas < 0):
        raise err("areas_m2", "facet areas must be >= 0", allowed=">= 0 m^2")
    if not np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6):
        raise err("normals_body", "normals must be unit vectors (to 1e-6)")
    check_inertia_magnitude(inertia, file, f"{prefix}/inertia_kg_m2")  # 1e308: eigvalsh fails
    if not np.allclose(inertia, inertia.T) or np.any(np.linalg.eigvalsh(0.5 * (inertia + inertia.T)) <= 0):
        raise err("inertia_kg_m2", "inertia must be symmetric positive definite")
    try:
        mass = float(g.attrs.get("mass_kg"))
    except (TypeError, ValueError):
        raise err("", "missing or bad attribute mass_kg") from None
    if not (np.isfinite(mass) and mass > 0):
        raise err("", "attribute mass_kg must be positive", value=mass)
    if "materials" not in g or not isinstance(g["materials"], h5py.Group):
        raise err("materials", "missing group")
    mg = g["materials"]
    nm = len(mg)
    if nm == 0 or nm > _MAX_MATERIALS:
        raise err("materials", "expected 1 or more materials", value=nm, allowed=f"<= {_MAX_MATERIALS}")
    mats = []
    for k in range(nm):
        if str(k) not in mg:
            raise err(f"materials/{k}", "missing material group (materials are numbered 0..M-1)")
        s = mg[str(k)]
        name = _text(s.attrs.get("name", f"material{k}"))
        brdf = _text(s.attrs.get("brdf", ""))
        try:
            params = json.loads(_text(s.attrs.get("params_json", "{}")))
        except json.JSONDecodeError as exc:
            raise err(f"materials/{k}", f"params_json is not JSON: {exc}") from None
        if not isinstance(params, dict) or not all(isinstance(v, (int, float)) for v in params.values()):
            raise err(f"materials/{k}", "params_json must map names to numbers", value=params)
        if brdf.startswith("tabulated"):
            from ..photometry.tabulated import TabulatedBRDF

            lab = f"materials/{k}"
            ti = ds("theta_i_deg", cap=_MAX_TABLE, parent=s, label=f"{lab}/theta_i_deg")
            po = ds("phi_o_deg", ti.shape, cap=_MAX_TABLE, parent=s, label=f"{lab}/phi_o_deg")
            fv = ds("brdf_sr", ti.shape, cap=_MAX_TABLE, parent=s, label=f"{lab}/brdf_sr")
            if ti.ndim != 1 or np.any(fv < 0) or np.any((ti < 0) | (ti >= 90)) or np.any(np.abs(po) > 90):
                raise err(lab, "BRDF table out of range",
                          allowed="theta_i in [0, 90), |phi_o| <= 90 deg, brdf >= 0")
            try:
                model = TabulatedBRDF(ti, po, fv, name=brdf)
            except ValueError as exc:
                raise err(lab, str(exc)) from None
        else:
            from ..photometry.brdf import get_brdf

            try:
                model = get_brdf(brdf, file=file, field=f"{prefix}/materials/{k}/brdf")
            except InputError:
                raise
            except Exception as exc:  # noqa: BLE001 - a broken plugin is bad input here
                raise err(f"materials/{k}", f"unknown BRDF {brdf!r}: {exc}") from None
        try:
            mats.append(Material(name, model, model.resolve_params(
                {p: float(v) for p, v in params.items()}, file=file,
                field=f"{prefix}/materials/{k}")))
        except InputError:
            raise
        except (TypeError, ValueError) as exc:
            raise err(f"materials/{k}", f"bad parameters: {exc}") from None
    if np.any((index < 0) | (index >= nm)):
        raise err("material", "material index out of range", allowed=f"0..{nm - 1}")
    verts = faces = None
    if "mesh" in g:
        verts = ds("vertices_m", cap=3 * MAX_MESH_VERTICES, parent=g["mesh"], label="mesh/vertices_m")
        faces = ds("faces", dtype=np.int64, cap=3 * MAX_MESH_VERTICES, parent=g["mesh"],
                   label="mesh/faces")
        if verts.ndim != 2 or verts.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 \
                or (faces.size and (faces.min() < 0 or faces.max() >= verts.shape[0])):
            raise err("mesh", "expected vertices (V, 3) and triangles (T, 3) indexing them")
    try:
        return Shape(_text(g.attrs.get("name", "stored")), areas, normals, centers,
                     [mats[i] for i in index], mass, inertia,
                     convex=bool(int(g.attrs.get("convex", 0))), tangents_body=tangents,
                     description=_text(g.attrs.get("description", "")),
                     source=_text(g.attrs.get("source", "")) or None,
                     vertices_m=verts, faces=faces)
    except ValueError as exc:
        raise err("", f"inconsistent shape: {exc}") from None
