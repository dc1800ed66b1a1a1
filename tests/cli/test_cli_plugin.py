"""`--plugin MODULE`: a user BRDF (and shape folder) used from the command line without
packaging it as an entry point."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from lightcurve.cli import main

PLUGIN = textwrap.dedent('''
    import numpy as np
    from lightcurve.photometry import register_brdf

    SHAPE_DIRS = ["plugin_shapes"]

    @register_brdf("lommel_seeliger_test", bounds={"albedo": (0.0, 1.0)})
    def lommel_seeliger(n, s, o, *, albedo=0.5):
        """Lommel-Seeliger: f_r = albedo / (4 pi) / ((n.s) + (n.o)), sr^-1."""
        ns = np.clip(np.sum(n * s, axis=-1), 0.0, None)
        no = np.clip(np.sum(n * o, axis=-1), 0.0, None)
        return albedo / (4 * np.pi) / np.maximum(ns + no, 1e-12)
''')

SHAPE = textwrap.dedent('''
    [shape]
    name = "ls_plate"
    mass_kg = 1.0
    inertia_diag_kg_m2 = [0.1, 0.1, 0.15]
    [materials.regolith]
    brdf = "lommel_seeliger_test"
    albedo = 0.2
    [[facets]]
    normal = [0.0, 0.0, 1.0]
    area_m2 = 1.0
    center_m = [0.0, 0.0, 0.0]
    material = "regolith"
''')


@pytest.fixture()
def plugin(tmp_path):
    """The plugin file; the process-wide plugin state is restored afterwards."""
    import lightcurve.plugins as P

    dirs, loaded = list(P._SHAPE_DIRS), dict(P._LOADED)
    yield _write_plugin(tmp_path)
    P._SHAPE_DIRS[:] = dirs
    P._LOADED.clear()
    P._LOADED.update(loaded)


def _write_plugin(tmp_path):
    (tmp_path / "plugin_shapes").mkdir()
    (tmp_path / "plugin_shapes" / "ls_plate.toml").write_text(SHAPE)
    p = tmp_path / "ls_plugin.py"
    p.write_text(PLUGIN)
    return p


def test_plugin_before_and_after_the_command(plugin, capsys):
    # without the plugin the shape is unknown (its folder and its BRDF come with the plugin)
    assert main(["shapes", "show", "ls_plate"]) == 2
    assert "unknown shape" in capsys.readouterr().err
    assert main(["--plugin", str(plugin), "shapes", "show", "ls_plate"]) == 0
    assert "lommel_seeliger_test" in capsys.readouterr().out
    assert main(["shapes", "validate", "ls_plate", "--plugin", str(plugin)]) == 0
    from lightcurve.photometry import get_brdf

    n = np.array([0.0, 0.0, 1.0])
    s = np.array([0.0, 0.6, 0.8])
    f = get_brdf("lommel_seeliger_test").evaluate(n, s, n, {"albedo": 0.2})
    assert f == pytest.approx(0.2 / (4 * np.pi) / 1.8)


def test_bad_plugins_are_input_errors(tmp_path, capsys):
    assert main(["--plugin", "no_such_module_xyz", "sites", "list"]) == 2
    assert "plugin module not found" in capsys.readouterr().err
    bad = tmp_path / "broken.py"
    bad.write_text("raise RuntimeError('boom')\n")
    assert main(["sites", "list", "--plugin", str(bad)]) == 2
    assert "plugin failed to import: RuntimeError: boom" in capsys.readouterr().err
    assert main(["sites", "list", "--plugin", str(tmp_path / "missing.py")]) == 2
