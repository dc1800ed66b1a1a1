from __future__ import annotations

import pytest

from lightcurve._paths import data_dir


@pytest.fixture(scope="session")
def thesis_fast_spin():
    """Bernard (2021) §9.3.3 LEO fast-spin case, controlled, one site (scenario path)."""
    return str(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")


SYMMETRIC_CUBE = """
[shape]
name = "sym_cube"
description = "1U cube, one material on all six faces (octahedral symmetry)"
mass_kg = 1.33
inertia_diag_kg_m2 = [0.0022166666666666667, 0.0022166666666666667, 0.0022166666666666667]

[materials.all]
brdf = "cook_torrance"
xi = 0.3
a = 0.8
m = 0.2
""" + "".join(f"""
[[facets]]
normal = {n}
area_m2 = 0.01
center_m = {[0.05 * x for x in n]}
material = "all"
""" for n in ([1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0],
              [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]))


@pytest.fixture(scope="session")
def sym_cube_library(tmp_path_factory):
    """A shape library folder holding ``sym_cube`` (SYMMETRIC_CUBE)."""
    d = tmp_path_factory.mktemp("symcube")
    (d / "sym_cube.toml").write_text(SYMMETRIC_CUBE)
    return d
