"""Self-contained lightcurve files: the stored shape, the validated scenario, and a user
library shape through simulate → invert → compare → diagnose → fit-reflection without
naming the library again."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
import recgen as G

from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.cli import main
from lightcurve.io.lightcurve_h5 import read_lightcurve
from lightcurve.photometry import apparent_magnitude, load_shape
from lightcurve.studies.scenario import load_scenario, parse_scenario, scenario_from_lightcurve
from lightcurve.studies.simulate import simulate

# the bundled default scenario is an umbral pass modelled as sunlit (Bernard's cases)
pytestmark = pytest.mark.filterwarnings("ignore:.*Earth's shadow")


def _scenario_text(shape="boxpanel", seconds=60.0):
    text = (data_dir("pipelines") / "default.toml").read_text()
    return (text.replace('name = "cube_1u"', f'name = "{shape}"')
            .replace("duration_s = 360.0", f"duration_s = {seconds}")
            .replace("[[0.0, 360.0]]", f"[[0.0, {seconds}]]"))


def _mags(shape, n=50, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    s, o = rng.standard_normal((2, n, 3))
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    o /= np.linalg.norm(o, axis=1, keepdims=True)
    with np.errstate(divide="ignore"):
        return apparent_magnitude(shape, q, s, o, np.full(n, 1e6), np.full(n, 1.496e11))


def test_stored_shape_round_trip_mesh_and_table(tmp_path):
    """The stored shape reproduces the magnitudes of the loaded one exactly (mesh library
    shape; and a measured-table BRDF, whose samples the file carries)."""
    lib = tmp_path / "lib"
    G.write_box_library(lib)
    shape = load_shape("boxpanel", library_dirs=[lib])
    sc = parse_scenario(_scenario_text(), file=str(tmp_path / "s.toml"), library_dirs=[lib])
    lc = simulate(sc)
    assert lc.shape is sc.shape
    p = lc.write(tmp_path / "a.h5")
    back = read_lightcurve(p)
    assert back.shape.name == "boxpanel" and back.shape.faces is not None
    np.testing.assert_array_equal(_mags(back.shape), _mags(shape))
    # a tabulated BRDF (Fankhauser et al. 2023 table format, made-up values)
    tab = tmp_path / "table.txt"
    rows = [f"{ti} -180 {po} 0 {0.1 + 0.5 * np.exp(-((po - ti) / 5.0) ** 2):.6f}"
            for ti in (5.0, 40.0, 75.0) for po in np.arange(-85.0, 86.0, 5.0)]
    tab.write_text("# phi_i theta_i phi_o theta_o brdf\n" + "\n".join(rows) + "\n")
    (tmp_path / "plate.toml").write_text(
        '[shape]\nname = "plate"\nmass_kg = 1.0\ninertia_diag_kg_m2 = [1.0, 1.0, 1.0]\n'
        '[materials.m]\nbrdf = "tabulated"\ntable = "table.txt"\n'
        '[[facets]]\nnormal = [0.0, 0.0, 1.0]\narea_m2 = 2.0\ncenter_m = [0.0, 0.0, 0.0]\n'
        'material = "m"\n')
    plate = load_shape(tmp_path / "plate.toml")
    lc2 = back.subset(np.arange(3))
    lc2.shape = plate
    b2 = read_lightcurve(lc2.write(tmp_path / "b.h5"))
    np.testing.assert_allclose(_mags(b2.shape), _mags(plate), rtol=0, atol=1e-9)


def test_hostile_shape_group_is_refused(tmp_path):
    lc = simulate(load_scenario(data_dir("pipelines") / "default.toml"))
    p = lc.write(tmp_path / "a.h5")
    with h5py.File(p, "r+") as h:
        h["shape/normals_body"][0] = [1.0, 1.0, 0.0]           # not a unit vector
    with pytest.raises(InputError, match="shape/normals_body"):
        read_lightcurve(p)
    p = lc.write(tmp_path / "b.h5")
    with h5py.File(p, "r+") as h:
        h["shape/materials/0"].attrs["params_json"] = json.dumps({"xi": 2.0, "a": 0.5, "m": 0.1})
    with pytest.raises(InputError, match="xi"):
        read_lightcurve(p)


def test_scenario_from_file_needs_neither_library_nor_site_folder(tmp_path):
    """A file simulated with a user shape and a user site folder re-validates its scenario
    from what it carries."""
    lib = tmp_path / "lib"
    G.write_box_library(lib)
    sites = tmp_path / "sites"
    sites.mkdir()
    (sites / "home.toml").write_text('lat_deg = 34.0\nlon_deg = -106.9\nheight_m = 1500.0\n')
    text = _scenario_text().replace('name = "socorro"', 'name = "home"')
    f = tmp_path / "s.toml"
    f.write_text(text)
    lc = simulate(load_scenario(f, library_dirs=[lib], site_dirs=[sites]))
    back = read_lightcurve(lc.write(tmp_path / "a.h5"))
    sc = scenario_from_lightcurve(back, tmp_path / "a.h5")
    assert sc.shape.name == "boxpanel" and sc.sites[0].site.id == "home"
    assert sc.sites[0].site.lat_deg == 34.0


def test_inline_site_id_rule(tmp_path):
    text = _scenario_text("cube_1u")
    base = text.split("[[sites]]")[0]
    rest = text.split("[measurement]")[1]

    def sites(block):
        return parse_scenario(base + block + "[measurement]" + rest, file="<t>")

    sc = sites('[[sites]]\nname = "My Site 2"\nlat_deg = 34.0\nlon_deg = -106.9\nheight_m = 10.0\n'
               '[[sites]]\nlat_deg = 35.0\nlon_deg = -106.0\nheight_m = 0.0\n'
               '[[sites]]\nid = "x9"\nname = "Anything"\nlat_deg = 1.0\nlon_deg = 2.0\nheight_m = 3.0\n')
    assert [s.site.id for s in sc.sites] == ["my-site-2", "site-2", "x9"]
    with pytest.raises(InputError, match="two \\[\\[sites\\]\\] entries with one id"):
        sites('[[sites]]\nname = "socorro"\n[[sites]]\nname = "socorro"\n')


def test_invert_without_truth_needs_an_initial_estimate(tmp_path, capsys):
    """A truth-free file asked to start from the truth, or from a given estimate without one,
    is refused naming what to give (without --initial it would run the global
    initialisation: tests/acquisition)."""
    lc = simulate(load_scenario(data_dir("pipelines") / "default.toml"))
    lc.truth_q = lc.truth_omega_rad_s = lc.truth_mag = None
    p = lc.write(tmp_path / "real.h5")
    rc = main(["invert", str(p), "-o", str(tmp_path / "o"), "--workers", "1", "-q",
               "--initial", "truth"])
    assert rc == 2
    err = json.loads((tmp_path / "o" / "summary.json").read_text())["real"]["error"]
    assert "truth" in err and "global" in err
    rc = main(["invert", str(p), "-o", str(tmp_path / "o2"), "--workers", "1", "-q",
               "--initial", "given"])
    assert rc == 2
    assert "--initial-q" in capsys.readouterr().err


def test_user_library_shape_through_every_command(tmp_path, capsys):
    """simulate --library, then invert, diagnose and fit-reflection with no library option
    (the file carries the shape); compare takes --library like simulate."""
    lib = tmp_path / "mylib"
    G.write_box_library(lib)
    s = tmp_path / "s.toml"
    s.write_text(_scenario_text())
    h5 = tmp_path / "sim.h5"
    assert main(["simulate", str(s), "-o", str(h5), "--library", str(lib)]) == 0
    assert main(["invert", str(h5), "-o", str(tmp_path / "inv"), "--workers", "1", "-q"]) == 0
    summ = json.loads((tmp_path / "inv" / "summary.json").read_text())["sim"]
    assert summ["inside_3sigma"]
    assert main(["diagnose", str(h5), "-o", str(tmp_path / "diag"), "-q", "--max-effects", "1",
                 "--cv", "none"]) == 0
    assert main(["fit-reflection", str(h5), "-o", str(tmp_path / "fr"), "--params", "xi",
                 "--facets", "0", "--max-steps", "4000", "-q"]) == 0
    st = tmp_path / "study.toml"
    st.write_text('[study]\nname = "lib"\nseed = 3\nruns = 1\nscenario = "s.toml"\n[grid]\n'
                  'filter = ["ukf"]\ndynamics = ["controlled"]\nsites = [1]\n'
                  'sigma_theta_deg = [3.0]\nsigma_omega_deg_s = [0.02]\nr_percent = [1.0]\n')
    assert main(["compare", str(st), "-o", str(tmp_path / "cmp"), "--library", str(lib),
                 "--workers", "1", "-q"]) == 0
    out = capsys.readouterr()
    assert "unknown shape" not in out.err
    # without --library the same study names what is missing
    assert main(["compare", str(st), "-o", str(tmp_path / "cmp2"), "--workers", "1", "-q"]) == 2
    assert "boxpanel" in capsys.readouterr().err
