"""docs/formats.md stays true: every marked example loads with the package's reader, and the
HDF5 tables list what the writers store.

Each ``<!-- example: KIND FILE [key=value …] -->`` marker is followed by one fenced block; all
blocks are written under a temporary folder first (examples refer to each other: a shape to its
mesh and BRDF table, a recording to its scenario), then each is loaded by the reader of KIND
and checked against the values written in the example.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from lightcurve._paths import data_dir

DOC = Path(__file__).resolve().parents[2] / "docs" / "formats.md"
_MARK = re.compile(r"<!-- example: (\S+) (\S+)((?: \S+=\S+)*) -->\n```[a-z]*\n(.*?)\n```", re.S)


def _examples():
    out = []
    for m in _MARK.finditer(DOC.read_text()):
        opts = dict(o.split("=", 1) for o in m.group(3).split())
        out.append((m.group(1), m.group(2), opts, m.group(4) + "\n"))
    return out


EXAMPLES = _examples()


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    root = tmp_path_factory.mktemp("formats")
    # the study example names its scenarios relative to pipelines/studies/
    (root / "pipelines").mkdir()
    (root / "pipelines" / "thesis").symlink_to(data_dir("pipelines") / "thesis")
    for _kind, name, _opts, text in EXAMPLES:
        p = root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return root


def test_every_kind_has_an_example():
    kinds = {k for k, *_ in EXAMPLES}
    assert kinds >= {"scenario", "shape", "mesh", "materials", "brdf-table", "site", "recording",
                     "study", "css-config", "css-study", "plugin"}


@pytest.mark.parametrize("kind, name, opts, text", EXAMPLES, ids=[e[1] for e in EXAMPLES])
def test_example_loads(kind, name, opts, text, written):
    p = written / name
    if kind == "scenario":
        from lightcurve.studies.scenario import load_scenario

        sc = load_scenario(p)
        assert sc.name == re.search(r'name = "([^"]+)"', text).group(1)
    elif kind == "shape":
        from lightcurve.photometry import load_shape
        from lightcurve.photometry.shapes_io import NONCONVEX_NOTE, validate_shape

        sh = load_shape(p)
        assert sh.name == p.stem
        assert [x for x in validate_shape(p) if NONCONVEX_NOTE not in x] == []
        if p.stem == "plate_probe":  # the facet list as written
            np.testing.assert_allclose(sh.areas_m2, [0.5, 0.5])
            np.testing.assert_allclose(np.diag(sh.inertia_kg_m2), [0.5, 1.7, 2.1])
        if p.stem == "tetra":  # 4 triangles, none coplanar: 4 facets; the (1,1,1) face is a cell
            assert sh.n_facets == 4
            k = int(np.argmax(sh.normals_body @ (np.ones(3) / np.sqrt(3))))
            assert sh.materials[k].brdf.name == "phong"
    elif kind == "mesh":
        import trimesh

        assert len(trimesh.load(str(p), force="mesh").faces) == 4
    elif kind == "materials":
        from lightcurve.photometry import load_shape

        sh = load_shape((written / opts["mesh"], p))
        assert sh.n_facets == 4 and all(m.brdf.name == "lambert" for m in sh.materials)
    elif kind == "brdf-table":
        from lightcurve.photometry import TabulatedBRDF

        b = TabulatedBRDF.from_csv(p)
        np.testing.assert_allclose(b.incidences_deg, [10.0, 50.0])
        # in the plane of incidence the table's own samples come back (mirror of 10°: 0.5)
        th = np.radians(10.0)
        n, s = np.array([0, 0, 1.0]), np.array([-np.sin(th), 0, np.cos(th)])
        o = np.array([np.sin(th), 0, np.cos(th)])
        assert b.evaluate(n, s, o, {"scale": 1.0}) == pytest.approx(0.5, rel=1e-6)
    elif kind == "site":
        from lightcurve.geometry.sites import load_sites

        site = load_sites([p.parent])["my_dome"]
        assert (site.lat_deg, site.lon_deg, site.height_m) == (47.3769, 8.5417, 420.0)
        assert site.horizon_rad(np.radians(45.0)) == pytest.approx(np.radians(17.5))
    elif kind == "recording":
        from lightcurve.io.recording import read_recording
        from lightcurve.studies.scenario import load_scenario

        lc = read_recording(p, load_scenario(written / opts["scenario"]))
        assert len(lc) == 3 and np.all(lc.lit_fraction == 1.0)
        np.testing.assert_allclose(lc.mag, [12.94, 14.07, 12.41])
        np.testing.assert_allclose(lc.t, [70.0, 145.0, 225.0])
        # the alt/az/range rows are the default scenario's pass: same object positions
        import warnings

        import lightcurve

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = lightcurve.simulate(data_dir("pipelines") / "default.toml")
        k = np.searchsorted(ref.t, lc.t)
        assert np.max(np.linalg.norm(ref.r_obj_eci_m[k] - lc.r_obj_eci_m, axis=1)) < 50.0
    elif kind == "study":
        from lightcurve.studies.study import load_study

        st = load_study(p)
        assert len(st.cells) == 96
    elif kind == "css-config":
        from lightcurve.css.configurations import load_configuration

        css = load_configuration(p)
        assert css.normals.shape == (3, 3)
        np.testing.assert_allclose(np.degrees(css.fov_half_angle_rad), [80.0, 60.0, 80.0])
    elif kind == "css-study":
        from lightcurve.css.study import load_css_study

        spec = load_css_study(p)
        assert spec.runs == 20 and spec.name == "css-demo"
    elif kind == "plugin":
        from lightcurve.photometry import get_brdf
        from lightcurve.plugins import load_plugin

        load_plugin(p)
        n = np.array([0.0, 0.0, 1.0])
        s, o = np.array([0.0, 0.6, 0.8]), np.array([0.0, 0.0, 1.0])
        assert get_brdf("minnaert_plugin").evaluate(n, s, o, {"albedo": 0.3, "k": 1.0}) == \
            pytest.approx(get_brdf("lambert").evaluate(n, s, o, {"albedo": 0.3}))
    else:  # pragma: no cover - a new kind needs a reader here
        pytest.fail(f"no reader for example kind {kind!r}")


# ---------------------------------------------------------------------------------------
def _table_names(section_title):
    """Backticked dataset/attribute names in the first column of a section's table."""
    text = DOC.read_text()
    i = text.index(section_title)
    j = text.find("\n#", i + len(section_title))
    names = set()
    for line in text[i:j].splitlines():
        if line.startswith("| ") and not line.startswith("| path") and not line.startswith("| ---"):
            first = line.split("|")[1]
            names.update(re.findall(r"`([^`]+)`", first))
    return names


def _file_names(path):
    import h5py

    out = set()
    with h5py.File(path, "r") as h:
        out.update(h.attrs)
        h.visititems(lambda n, o: out.add(n) if isinstance(o, h5py.Dataset) else None)
    return out


def _documented(name, doc):
    if name in doc or name.startswith("meta_"):
        return True
    return any(name.startswith(d.rstrip("*") + "/") for d in doc)  # groups such as clouds/


def test_hdf5_tables_match_the_writers(tmp_path):
    import warnings

    import lightcurve
    from lightcurve.css.recording import write_css_recording

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lc = lightcurve.simulate(data_dir("pipelines") / "default.toml")
    lc_doc = _table_names("## Lightcurve HDF5")
    got = _file_names(lc.write(tmp_path / "lc.h5"))
    assert {g for g in got if not _documented(g, lc_doc)} == set()
    assert {"t", "mag", "mag_sigma", "site", "sites/name", "geometry/r_obj_eci_m", "truth/q",
            "epoch_utc", "format_version"} <= got

    est = lightcurve.invert(lc, "ukf", seed=1)
    est_doc = _table_names("## Estimate HDF5")
    got = _file_names(est.write(tmp_path / "e.h5"))
    assert {g for g in got if not _documented(g, est_doc)} == set()
    assert {"format", "method", "t", "q", "omega_rad_s", "cov", "innovations", "nees"} <= got

    from lightcurve.css.configurations import configuration_by_name
    from lightcurve.css.truth import CSSScenario, simulate_css

    css = configuration_by_name("cube")
    r = simulate_css(CSSScenario(css, duration_s=20.0, dt_s=1.0), 1)
    css_doc = _table_names("### CSS recording HDF5")
    got = _file_names(write_css_recording(tmp_path / "c.h5", r, css, "2015-03-01T00:00:00Z", True))
    assert {g for g in got if not _documented(g, css_doc)} == set()
