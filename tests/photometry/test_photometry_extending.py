"""Does exactly what docs/extending.md says, in order, with the code blocks taken from the page.

The page's Python blocks are executed as written and its TOML block is written to a library
folder, so a change to the page that breaks the walk-through fails here.
"""

import re
from pathlib import Path

import numpy as np
import pytest

from lightcurve.cli import main
from lightcurve.photometry import AU_M, get_brdf, unregister_brdf

DOC = Path(__file__).resolve().parents[2] / "docs" / "extending.md"


def _blocks(lang):
    return re.findall(rf"```{lang}\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


@pytest.fixture
def clean_registry():
    yield
    unregister_brdf("minnaert")


def test_extending_walkthrough(tmp_path, capsys, clean_registry):
    py = _blocks("python")
    toml = _blocks("toml")
    assert len(py) == 3 and len(toml) == 2

    # 1. add a BRDF (block 1), check it against Lambert (block 2)
    ns: dict = {}
    exec(py[0], ns)
    exec(py[1], ns)
    b = get_brdf("minnaert")
    assert b.param_names == ("albedo", "k")
    # Minnaert at k = 1.2, n·s = 0.8, n·o = 1: 0.4/π · 0.8^0.2 (hand value)
    n = np.array([0.0, 0.0, 1.0])
    assert b.evaluate(n, np.array([0.0, 0.6, 0.8]), n, {"albedo": 0.4, "k": 1.2}) == \
        pytest.approx(0.4 / np.pi * 0.8**0.2, rel=1e-12)

    # the pyproject snippet names the entry-point group the registry scans
    assert '[project.entry-points."lightcurve.brdfs"]' in toml[0]
    from lightcurve.photometry.brdf import ENTRY_POINT_GROUP
    assert ENTRY_POINT_GROUP == "lightcurve.brdfs"

    # 2. add a shape: the TOML block goes to my_shapes/plate_probe.toml
    assert toml[1].startswith("# my_shapes/plate_probe.toml")
    lib = tmp_path / "my_shapes"
    lib.mkdir()
    (lib / "plate_probe.toml").write_text(toml[1])

    # the console commands, run through the CLI entry point
    assert main(["shapes", "--library", str(lib), "validate", "plate_probe"]) == 0
    assert capsys.readouterr().out.strip() == "plate_probe: OK"
    assert main(["shapes", "--library", str(lib), "show", "plate_probe"]) == 0
    assert "minnaert" in capsys.readouterr().out

    # block 3, with the inputs the page describes
    ns3 = {"q": np.array([[1.0, 0.0, 0.0, 0.0]]), "sun_dir_eci": np.array([[0.0, 0.6, 0.8]]),
           "obs_dir_eci": np.array([[0.0, 0.0, 1.0]]), "range_obs_m": np.array([1e6]),
           "range_sun_m": np.array([AU_M])}
    code = py[2].replace('library_dirs=["my_shapes"]', f"library_dirs=[{str(lib)!r}]")
    exec(code, ns3)
    shape, m = ns3["shape"], ns3["m"]
    assert shape.n_facets == 2 and list(shape.model_ids) == [-1, 1]
    # only the Minnaert top is lit and seen: Φ = 0.5 m² · 0.8 · 1 · 0.4/π · 0.8^0.2
    flux = 0.5 * 0.8 * 0.4 / np.pi * 0.8**0.2
    assert m[0] == pytest.approx(-26.74 - 2.5 * np.log10(flux / 1e12), abs=1e-9)
