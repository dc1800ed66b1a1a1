"""Special files reach no reader: FIFOs, /dev/zero, folders and links to them are refused with
one line, never read until memory runs out or blocked on for ever (lightcurve.io.safe_open).

Every call runs under a SIGALRM watchdog: a reader that blocks on a FIFO or reads /dev/zero
without end fails the test after a few seconds instead of hanging the suite.
"""

from __future__ import annotations

import contextlib
import os
import signal
from pathlib import Path

import pytest

from hardening_util import small_curve
from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.cli import main

TIMEOUT_S = 20  # generous on a loaded 2-core machine; the refusals take milliseconds


@contextlib.contextmanager
def deadline(seconds=TIMEOUT_S):
    """Raise TimeoutError in this thread after ``seconds`` (a blocked open or read is
    interrupted by the signal)."""

    def on_alarm(signum, frame):
        raise TimeoutError(f"still running after {seconds} s: blocked on a special file?")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def run_cli(argv, capsys):
    with deadline():
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:
            code = exc.code
    out, err = capsys.readouterr()
    return code, err + out  # `shapes validate` lists problems on stdout


@pytest.fixture()
def special(tmp_path):
    """A FIFO, a link to /dev/zero, a folder named like a file, a link to the FIFO."""
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    zero = tmp_path / "zero.toml"
    zero.symlink_to("/dev/zero")
    folder = tmp_path / "folder.h5"
    folder.mkdir()
    link_fifo = tmp_path / "link_to_pipe.h5"
    link_fifo.symlink_to(fifo)
    return {"fifo": fifo, "zero": zero, "devzero": Path("/dev/zero"), "folder": folder,
            "link_fifo": link_fifo, "dir": tmp_path}


def _readers():
    from lightcurve.css.albedo import load_albedo_map
    from lightcurve.css.recording import read_css_recording
    from lightcurve.filters.result import read_estimate
    from lightcurve.io.lightcurve_h5 import read_lightcurve
    from lightcurve.io.recording import read_recording
    from lightcurve.io.tomlio import load_toml
    from lightcurve.photometry.tabulated import load_brdf_table
    from lightcurve.studies.runner import read_run
    from lightcurve.studies.scenario import load_scenario

    return {"load_toml": load_toml, "load_scenario": load_scenario,
            "read_recording (CSV)": read_recording, "read_lightcurve": read_lightcurve,
            "read_css_recording": read_css_recording, "read_estimate": read_estimate,
            "read_run": read_run, "load_albedo_map": load_albedo_map,
            "load_brdf_table": load_brdf_table}


@pytest.mark.parametrize("kind", ["fifo", "zero", "devzero", "folder", "link_fifo"])
def test_every_reader_refuses_special_files(kind, special):
    """Each reader: InputError naming the file and what it is, within the deadline."""
    path = special[kind]
    for name, reader in _readers().items():
        with deadline():
            with pytest.raises(InputError) as ei:
                reader(path)
        text = str(ei.value)
        assert str(path) in text, (name, text)
        assert "not a regular" in text or "is a directory" in text, (name, text)


def test_mesh_and_materials_special_files_refused(special, tmp_path):
    """A shape whose mesh is a FIFO, whose BRDF table is /dev/zero, or a scenario whose
    materials file is /dev/zero or a FIFO: refused, never read (nor blocked on)."""
    from lightcurve.photometry import load_shape

    src = (data_dir("shapes") / "box_wing_mesh.toml").read_text()
    mesh_fifo = tmp_path / "hull.obj"
    os.mkfifo(mesh_fifo)
    shp = tmp_path / "s.toml"
    shp.write_text(src.replace('mesh = "box_wing_mesh.obj"', f'mesh = "{mesh_fifo}"'))
    assert str(mesh_fifo) in shp.read_text()
    with deadline(), pytest.raises(InputError, match="FIFO"):
        load_shape(shp)
    # a tabulated material whose table is /dev/zero
    cube = (data_dir("shapes") / "cube_1u.toml").read_text()
    import re

    tab = re.sub(r'brdf = "[a-z_]+"[^\[]*', 'brdf = "tabulated"\ntable = "/dev/zero"\n\n', cube,
                 count=1)
    assert 'table = "/dev/zero"' in tab
    (tmp_path / "tab.toml").write_text(tab)
    with deadline(), pytest.raises(InputError, match="character device"):
        load_shape(tmp_path / "tab.toml")
    # a scenario naming /dev/zero as its materials file
    p = tmp_path / "scen.toml"
    p.write_text(_mesh_scenario("/dev/zero"))
    from lightcurve.studies.scenario import load_scenario

    with deadline(), pytest.raises(InputError, match="/dev/zero"):
        load_scenario(p)
    # ... and a FIFO as its materials file (opening it for reading used to block for ever)
    mat_fifo = tmp_path / "materials.toml"
    os.mkfifo(mat_fifo)
    p.write_text(_mesh_scenario(str(mat_fifo)))
    with deadline(), pytest.raises(InputError, match="FIFO") as ei:
        load_scenario(p)
    assert str(mat_fifo) in str(ei.value)


def _mesh_scenario(materials: str) -> str:
    """The default scenario with its shape given as a mesh and a materials file."""
    text = (data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml").read_text()
    mesh = data_dir("shapes") / "box_wing_mesh.obj"
    out = text.replace('[shape]\nname = "cube_1u"',
                       f'[shape]\nmesh = "{mesh}"\nmaterials = "{materials}"')
    assert out != text
    return out


def test_site_folder_with_a_link_to_dev_zero(special, capsys):
    """`sites list --sites DIR` with DIR/x.toml -> /dev/zero: exit 2, one line."""
    d = special["dir"] / "sites"
    d.mkdir()
    (d / "evil.toml").symlink_to("/dev/zero")
    code, err = run_cli(["sites", "list", "--sites", d], capsys)
    assert code == 2 and "evil.toml" in err and "character device" in err
    (d / "evil.toml").unlink()
    os.mkfifo(d / "pipe.toml")
    code, err = run_cli(["sites", "list", "--sites", d], capsys)
    assert code == 2 and "FIFO" in err


@pytest.mark.parametrize("argv", [
    ["simulate", "{devzero}", "-o", "{dir}/x.h5"],
    ["simulate", "{fifo}", "-o", "{dir}/x.h5"],
    ["plot", "{link_fifo}", "-o", "{dir}/x.png"],
    ["plot", "{devzero}", "-o", "{dir}/x.png"],
    ["compare", "{devzero}", "-o", "{dir}/cmp", "--workers", "1"],
    ["compare", "{fifo}", "-o", "{dir}/cmp", "--workers", "1"],
    ["css", "study", "{devzero}", "--out", "{dir}/css"],
    ["css", "estimate", "{fifo}"],
    ["diagnose", "{devzero}", "--scenario", "{scen}", "-o", "{dir}/dg"],
    ["diagnose", "{link_fifo}", "-o", "{dir}/dg"],
    ["invert", "{link_fifo}", "-o", "{dir}/inv", "--workers", "1"],
    ["shapes", "validate", "{fifo}"],
])
def test_cli_special_file_inputs_exit_2(argv, special, capsys):
    fmt = {k: str(v) for k, v in special.items()}
    fmt["scen"] = str(data_dir("pipelines") / "default.toml")
    code, err = run_cli([a.format(**fmt) for a in argv], capsys)
    assert code == 2, err
    assert "not a regular" in err or "is a directory" in err, err


def test_csv_recording_size_cap(tmp_path, monkeypatch):
    """CSV recordings have a size cap (checked on the opened descriptor, before reading)."""
    import lightcurve.io.safe_open as so
    from lightcurve.io.recording import read_recording

    p = tmp_path / "big.csv"
    with open(p, "wb") as fh:  # sparse: the size is there, the bytes are not
        fh.truncate(so.CSV_MAX_BYTES + 1)
    with deadline(), pytest.raises(InputError, match="too large"):
        read_recording(p)


def test_embedded_scenario_cannot_name_files(tmp_path, capsys):
    """`diagnose file.h5` parses the scenario stored in the file: a mesh or materials path
    (here /dev/zero and an absolute mesh) is refused; a shape name with a path in the file's
    attrs is refused by invert."""
    lc = small_curve()
    lc.scenario_toml = _mesh_scenario("/dev/zero")
    f = tmp_path / "received.h5"
    lc.write(f)
    code, err = run_cli(["diagnose", f, "-o", tmp_path / "dg"], capsys)
    assert code == 2 and "may not name mesh or material files" in err, err

    lc2 = small_curve()
    lc2.attrs["shape"] = str(data_dir("shapes") / "cube_1u.toml")
    g = tmp_path / "path_shape.h5"
    lc2.write(g)
    code, err = run_cli(["invert", g, "-o", tmp_path / "inv", "--workers", "1", "-q"], capsys)
    assert code == 2 and "not a shape library name" in err, err


def test_embedded_scenario_cannot_name_an_albedo_map(tmp_path, capsys, monkeypatch):
    """A stored scenario's `[effects.earthshine] albedo = "<path>"` made `invert` look the
    path up (exit 0, or "file not found": an oracle of which files exist, and a file the
    scenario would read when simulated); refused before the path is touched. The same
    table in a scenario given as a file still works."""
    import lightcurve.physics.earthshine as es

    touched = []
    real = es.Path
    monkeypatch.setattr(es, "Path", lambda p: touched.append(str(p)) or real(p))
    from lightcurve.studies.scenario import load_scenario

    lc = small_curve()
    base = (data_dir("pipelines") / "thesis" /
            "leo-ic1-fast-spin-controlled-1site.toml").read_text()
    ok = tmp_path / "map.csv"
    ok.write_text("0.3\n")
    for target in ("/etc/passwd", str(ok)):
        lc.scenario_toml = base + f'\n[effects.earthshine]\nalbedo = "{target}"\n'
        f = tmp_path / "received.h5"
        lc.write(f)
        code, err = run_cli(["invert", f, "-o", tmp_path / "inv", "--workers", "1", "-q"],
                            capsys)
        assert code == 2 and f"{f}:scenario: field 'effects.earthshine.albedo'" in err, err
        assert "may not name files" in err and not touched, (err, touched)
    # a scenario file of the user's own may name its map
    p = tmp_path / "own.toml"
    p.write_text(lc.scenario_toml)
    assert load_scenario(p).name and touched == [str(ok)]


def _cap_readers():
    """(reader name, call on a path, its cap in bytes, file suffix) for every size-capped
    reader of the size table in docs/robustness.md not tested on its own elsewhere."""
    import lightcurve.io.safe_open as so
    from lightcurve.earth.albedo import load_albedo_map
    from lightcurve.geometry.tle import MAX_BYTES as TLE_MAX_BYTES
    from lightcurve.geometry.tle import load_element_sets
    from lightcurve.photometry import load_shape
    from lightcurve.photometry.tabulated import load_brdf_table

    def mesh_shape(path):  # a shape TOML whose mesh is the big file
        src = (data_dir("shapes") / "box_wing_mesh.toml").read_text()
        shp = path.with_name("shape.toml")
        shp.write_text(src.replace('mesh = "box_wing_mesh.obj"', f'mesh = "{path}"'))
        return load_shape(shp)

    return [("mesh (OBJ)", mesh_shape, so.MESH_MAX_BYTES, ".obj"),
            ("BRDF table", load_brdf_table, so.BRDF_MAX_BYTES, ".csv"),
            ("albedo map", load_albedo_map, so.ALBEDO_MAX_BYTES, ".csv"),
            ("JSON", so.read_json, so.JSON_MAX_BYTES, ".json"),
            ("element-set file", load_element_sets, TLE_MAX_BYTES, ".tle")]


@pytest.mark.parametrize("kind", ["mesh (OBJ)", "BRDF table", "albedo map", "JSON",
                                  "element-set file"])
def test_size_caps_of_the_other_readers(kind, tmp_path):
    """Mesh 200 MiB, BRDF table 64 MiB, albedo map 16 MiB, JSON 256 MiB, element sets
    64 MiB: a (sparse) file one byte over the cap is refused from its size, nothing read; a
    file at the cap passes the size check (it fails later, as the zeros it holds are no valid
    content, but not for its size)."""
    name, reader, cap, suffix = next(r for r in _cap_readers() if r[0] == kind)
    p = tmp_path / f"big{suffix}"
    with open(p, "wb") as fh:  # sparse: the size is there, the bytes are not
        fh.truncate(cap + 1)
    with deadline(), pytest.raises(InputError, match="too large") as ei:
        reader(p)
    assert str(p) in str(ei.value) and f"<= {cap} bytes" in str(ei.value), (name, ei.value)
    if cap <= 16 * 1024 * 1024:  # reading the zeros at the cap is cheap only for small caps
        os.truncate(p, cap)
        with deadline(), pytest.raises(InputError) as ei:
            reader(p)
        assert "too large" not in str(ei.value), (name, ei.value)


def test_a_file_larger_than_its_stat_size_is_cut_at_the_cap():
    """Whole-file reads stop at the cap + 1 byte whatever fstat said: /proc/self/maps is a
    regular file whose size reads as 0 (like a file that grows while it is read)."""
    from lightcurve.io.safe_open import read_bytes

    maps = Path("/proc/self/maps")
    if not maps.is_file() or maps.stat().st_size != 0:
        pytest.skip("needs Linux /proc (a regular file whose stat size is 0)")
    with deadline(), pytest.raises(InputError, match="grew past the limit") as ei:
        read_bytes(maps, max_bytes=64, track=False)
    assert str(maps) in str(ei.value)
    assert len(read_bytes(maps, max_bytes=1 << 24, track=False)) > 64
