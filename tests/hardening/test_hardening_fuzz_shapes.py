"""Fuzz: shape files (TOML facet lists, OBJ/STL meshes with a TOML material map).

Property: load_shape and validate_shape raise only InputError (naming the file) for
any damaged or hostile shape TOML, OBJ or STL; validate_shape returns a list of problems.
"""

from __future__ import annotations

import shutil
import struct
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardening_util import (damaged_bytes, dumps_toml, fuzz_settings, mutated_docs, new_tmp_dir,
                            only_input_error)
from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.photometry.shapes_io import load_shape, validate_shape

SHAPES = data_dir("shapes")
CUBE = tomllib.loads((SHAPES / "cube_1u.toml").read_text())
ROCKET_TOML = tomllib.loads((SHAPES / "rocket_body.toml").read_text())
ROCKET_OBJ = (SHAPES / "rocket_body.obj").read_bytes()

MATERIALS_ONLY = {"shape": {"name": "m", "mass_kg": 10.0, "default_material": "paint"},
                  "materials": {"paint": {"brdf": "lambert", "albedo": 0.3}}}


def _tmp() -> Path:
    return new_tmp_dir()


def _binary_stl(tris: np.ndarray) -> bytes:
    """Binary STL of triangles (n, 3, 3) — written here independently of trimesh."""
    out = bytearray(b"fuzz".ljust(80, b" "))
    out += struct.pack("<I", len(tris))
    for t in tris:
        out += struct.pack("<3f", 0, 0, 0) + struct.pack("<9f", *np.asarray(t, float).ravel()) + b"\0\0"
    return bytes(out)


TETRA = np.array([[[0, 0, 0], [0, 1, 0], [1, 0, 0]], [[0, 0, 0], [1, 0, 0], [0, 0, 1]],
                  [[0, 0, 0], [0, 0, 1], [0, 1, 0]], [[1, 0, 0], [0, 1, 0], [0, 0, 1]]], float)
GOOD_STL = _binary_stl(TETRA - 0.25)


@fuzz_settings(120)
@given(mutated_docs(CUBE))
def test_facet_list_toml_mutated(doc):
    d = _tmp()
    p = d / "fz.toml"
    p.write_text(dumps_toml(doc), encoding="utf-8")
    only_input_error("shape TOML (load_shape)", load_shape, p, file=p)
    probs = validate_shape(p)
    assert isinstance(probs, list) and all(isinstance(x, str) for x in probs)


@fuzz_settings(60)
@given(damaged_bytes((SHAPES / "cube_1u.toml").read_bytes()))
def test_facet_list_toml_damaged_bytes(data):
    p = _tmp() / "fz.toml"
    p.write_bytes(data)
    only_input_error("shape TOML (load_shape)", load_shape, p, file=p)


@fuzz_settings(60)
@given(mutated_docs(ROCKET_TOML))
def test_mesh_shape_toml_mutated(doc):
    d = _tmp()
    shutil.copy(SHAPES / "rocket_body.obj", d / "rocket_body.obj")
    p = d / "rb.toml"
    p.write_text(dumps_toml(doc), encoding="utf-8")
    out = only_input_error("mesh shape TOML (load_shape)", load_shape, p)
    if isinstance(out, InputError):  # the mesh or the TOML is named
        assert "rb.toml" in str(out) or "rocket_body.obj" in str(out) or "rocket_body" in str(out), str(out)


@fuzz_settings(80)
@given(st.one_of(damaged_bytes(ROCKET_OBJ), st.binary(max_size=400),
                 st.lists(st.sampled_from([b"v 1 2 3", b"v nan 0 0", b"v 1e400 0 0", b"f 1 2 3",
                                           b"f 1 2 999999", b"f -1 -2 -3", b"f 1 1 1", b"vn 0 0 1",
                                           b"mtllib ../../etc/passwd", b"usemtl x", b"o obj",
                                           b"v 0 0 0", b"v 1 0 0", b"v 0 1 0", b"f 1/1/1 2//2 3",
                                           b"\xff\xfe", b"#"]), max_size=30).map(b"\n".join)))
def test_obj_meshes(data):
    d = _tmp()
    mesh = d / "m.obj"
    mesh.write_bytes(data)
    mat = d / "m_materials.toml"
    mat.write_text(dumps_toml(MATERIALS_ONLY))
    out = only_input_error("OBJ mesh (load_shape)", load_shape, (mesh, mat))
    if isinstance(out, InputError):
        assert "m.obj" in str(out) or "m_materials.toml" in str(out), str(out)
    else:
        assert np.all(np.isfinite(out.normals_body)) and np.all(out.areas_m2 >= 0)


@fuzz_settings(80)
@given(st.one_of(damaged_bytes(GOOD_STL), st.binary(max_size=400),
                 st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=9,
                          max_size=27).map(lambda v: _binary_stl(np.resize(np.array(v), (len(v) // 9, 3, 3)))),
                 st.just(b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                         b"vertex 0 1 0\nendloop\nendfacet\nendsolid x\n"),
                 st.integers(0, 2**32 - 1).map(lambda n: b"x" * 80 + struct.pack("<I", n))))
def test_stl_meshes(data):
    d = _tmp()
    mesh = d / "m.stl"
    mesh.write_bytes(data)
    mat = d / "m_materials.toml"
    mat.write_text(dumps_toml(MATERIALS_ONLY))
    out = only_input_error("STL mesh (load_shape)", load_shape, (mesh, mat))
    if isinstance(out, InputError):
        assert "m.stl" in str(out) or "m_materials.toml" in str(out), str(out)


def test_stl_claiming_four_billion_triangles_is_refused():
    """A binary STL header claiming 2^32-1 triangles but carrying none: refused, not allocated."""
    d = _tmp()
    mesh = d / "liar.stl"
    mesh.write_bytes(b"x" * 80 + struct.pack("<I", 2**32 - 1))
    mat = d / "m.toml"
    mat.write_text(dumps_toml(MATERIALS_ONLY))
    with pytest.raises(InputError, match=r"liar\.stl"):
        load_shape((mesh, mat))


def test_huge_mesh_refused_from_its_size():
    d = _tmp()
    mesh = d / "huge.obj"
    with open(mesh, "wb") as fh:
        fh.truncate(300 * 1024 * 1024)  # sparse: no disk used
    mat = d / "m.toml"
    mat.write_text(dumps_toml(MATERIALS_ONLY))
    with pytest.raises(InputError, match=r"huge\.obj.*too large"):
        load_shape((mesh, mat))


def test_good_stl_loads():
    """The independent STL writer above produces a loadable tetrahedron (4 facets)."""
    d = _tmp()
    mesh = d / "t.stl"
    mesh.write_bytes(GOOD_STL)
    mat = d / "m.toml"
    mat.write_text(dumps_toml(MATERIALS_ONLY))
    shape = load_shape((mesh, mat))
    assert shape.n_facets == 4
    # total area of the unit right tetrahedron: 3 * 1/2 + sqrt(3)/2
    assert np.isclose(shape.areas_m2.sum(), 1.5 + np.sqrt(3) / 2)


# ----------------------------------------------------------------------------------------
# tabulated BRDF tables referenced by materials (brdf = "tabulated")
# ----------------------------------------------------------------------------------------
GOOD_TABLE = ("# phi_i theta_i phi_o theta_o brdf\n" + "\n".join(
    f"{zi} -180 {zo} 0 {0.1 + 0.01 * abs(zo - zi):.3f}" for zi in (5, 41.4, 60, 75)
    for zo in (-60, -30, 0, 30, 60))).encode()


@fuzz_settings(80)
@given(st.one_of(damaged_bytes(GOOD_TABLE), st.binary(max_size=300),
                 st.lists(st.sampled_from([b"5 -180 10 0 0.1", b"5 -180 nan 0 0.1", b"95 -180 0 0 1",
                                           b"5 -180 10 0 -1", b"5 0 10 0 0.1", b"5 -180 10 0 inf",
                                           b"7 -180 1 0 0.2", b"a b c d e", b"1 2 3", b"# c"]),
                          max_size=12).map(b"\n".join)))
def test_tabulated_brdf_tables(data):
    from lightcurve.photometry.tabulated import TabulatedBRDF

    p = _tmp() / "t.csv"
    p.write_bytes(data)
    only_input_error("BRDF table (TabulatedBRDF.from_csv)", TabulatedBRDF.from_csv, p, file=p)


def test_huge_brdf_table_refused_from_size():
    from lightcurve.photometry.tabulated import TabulatedBRDF

    p = _tmp() / "huge.csv"
    with open(p, "wb") as fh:
        fh.truncate(128 * 1024 * 1024)
    with pytest.raises(InputError, match=r"huge\.csv.*too large"):
        TabulatedBRDF.from_csv(p)
