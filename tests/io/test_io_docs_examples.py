"""The recording, import, element-set and passes examples of docs/formats.md run as written."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import numpy as np

from lightcurve.cli import main
from lightcurve.io.lightcurve_h5 import read_lightcurve
from lightcurve.io.recording import recording_spec_from_section

DOC = Path(__file__).resolve().parents[2] / "docs" / "formats.md"


def example(name):
    """The code block after ``<!-- cli-example: name -->`` in docs/formats.md."""
    m = re.search(rf"<!-- cli-example: {re.escape(name)} -->\s*```\w*\n(.*?)```", DOC.read_text(), re.S)
    assert m, f"example {name!r} missing from docs/formats.md"
    return m.group(1)


def run(cmd, cwd, monkeypatch):
    monkeypatch.chdir(cwd)
    argv = shlex.split(cmd.strip())
    assert argv[0] == "lightcurve"
    return main(argv[1:])


def test_recording_csv_and_import_command(tmp_path, monkeypatch):
    (tmp_path / "rec.csv").write_text(example("recording-csv"))
    assert run(example("import-command"), tmp_path, monkeypatch) == 0
    a = read_lightcurve(tmp_path / "obs.A.h5")      # one band: no band in the name
    assert len(a) == 3 and a.camera_names == ["mount_lemmon/c1", "mount_lemmon/c2"]
    assert a.attrs["band"] == "V" and a.attrs["sun_mag"] == -26.74
    np.testing.assert_allclose(a.exposure_s, 0.5)
    assert len(read_lightcurve(tmp_path / "obs.B.h5")) == 1


def test_recording_mapping_example_validates():
    import tomllib

    spec = recording_spec_from_section(tomllib.loads(example("recording-mapping"))["recording"])
    assert spec.height_unit == "km" and spec.site == "mount_lemmon"


def test_element_set_import_and_passes(tmp_path, monkeypatch, capsys):
    (tmp_path / "objects.tle").write_text(example("elements-3le"))
    (tmp_path / "elements.csv").write_text(example("elements-csv"))
    assert run(example("elements-import"), tmp_path, monkeypatch) == 0
    one = read_lightcurve(tmp_path / "demo.91001.h5")
    assert len(one) == 2 and one.attrs["element_set"] == "DEMOSAT 1 (91001)"
    assert read_lightcurve(tmp_path / "demo.DEMOSAT_2.h5").attrs["geometry_source"] == "elements"
    capsys.readouterr()
    assert run(example("passes-command"), tmp_path, monkeypatch) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("object,norad,rise_utc")
