"""Outputs: never over an input, a failed write in a batch is recorded and the batch goes on,
one run per study folder (lock), temporary files of killed writers removed (never a live
writer's), file modes from the umask.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hardening_util import small_curve
from lightcurve import InputError
from lightcurve._paths import data_dir
from test_hardening_special_files import run_cli


def _curve(path):
    small_curve().write(path)
    return path.read_bytes()


def test_output_same_as_input_exit_2(tmp_path, capsys):
    """`plot leo.h5 -o leo.h5`, `simulate s.toml -o s.toml`, `css estimate rec.h5 --out
    rec.h5` and an output that is a hard link of the input: exit 2, input unchanged."""
    leo = tmp_path / "leo.h5"
    before = _curve(leo)
    code, err = run_cli(["plot", leo, "-o", leo], capsys)
    assert code == 2 and "overwrite an input" in err, err
    assert leo.read_bytes() == before
    link = tmp_path / "other-name.png"
    os.link(leo, link)
    code, err = run_cli(["plot", leo, "-o", link], capsys)
    assert code == 2 and "overwrite an input" in err and leo.read_bytes() == before

    scen = tmp_path / "s.toml"
    text = (data_dir("pipelines") / "default.toml").read_text()
    scen.write_text(text)
    code, err = run_cli(["simulate", scen, "-o", scen], capsys)
    assert code == 2 and "overwrite an input" in err and scen.read_text() == text

    rec = tmp_path / "rec.h5"
    _css_recording(rec)
    rb = rec.read_bytes()
    code, err = run_cli(["css", "estimate", rec, "--estimator", "wavg", "--out", rec], capsys)
    assert code == 2 and "overwrite an input" in err and rec.read_bytes() == rb


@pytest.mark.parametrize("argv, frag", [
    (["invert", "{leo}", "-o", "{file}", "--workers", "1", "-q"], "is not a folder"),
    (["period", "{leo}", "-o", "{file}"], "is not a folder"),
    (["diagnose", "{leo}", "-o", "{file}"], "is not a folder"),
    (["compare", "{scen}", "-o", "{file}", "--workers", "1"], "is not a folder"),
    (["css", "study", "{scen}", "--out", "{file}"], "is not a folder"),
    (["invert", "{leo}", "-o", "{file}/sub", "--workers", "1", "-q"], "is not a folder"),
    (["simulate", "{scen}", "-o", "{folder}"], "is a folder"),
    (["plot", "{leo}", "-o", "{folder}"], "is a folder"),
    (["plot", "{leo}", "-o", "{file}/sub/x.png"], "is not a folder"),
    (["css", "estimate", "{rec}", "--out", "{folder}"], "is a folder"),
])
def test_output_path_of_the_wrong_kind_exit_2_before_work(argv, frag, tmp_path, capsys):
    """`-o DIR` naming an existing file, `-o FILE` naming an existing folder, or an output
    below a regular file: a usage error at parse time (exit 2, one argparse line naming the
    option and the path), before any work. These used to fail with exit 1 (FileExistsError,
    IsADirectoryError, NotADirectoryError) — `simulate` and `plot` only after all the work."""
    leo = tmp_path / "leo.h5"
    _curve(leo)
    rec = tmp_path / "rec.h5"
    _css_recording(rec)
    file = tmp_path / "notes.txt"
    file.write_text("keep me\n")
    folder = tmp_path / "results"
    folder.mkdir()
    scen = data_dir("pipelines") / "default.toml"
    fmt = {"leo": leo, "rec": rec, "file": file, "folder": folder, "scen": scen}
    before = sorted(p.name for p in tmp_path.rglob("*"))
    code, err = run_cli([a.format(**fmt) for a in argv], capsys)
    assert code == 2, err
    last = err.strip().splitlines()[-1]
    assert "argument -o/--output" in last or "argument --out" in last, last
    assert frag in last, last
    assert file.read_text() == "keep me\n"
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # nothing written


def test_output_path_of_the_right_kind_is_accepted(tmp_path):
    """The parse-time output check accepts existing folders, new paths below new folders, and
    existing files for file outputs (replaced atomically later)."""
    import argparse

    from lightcurve.cli._args import output_path

    (tmp_path / "d").mkdir()
    (tmp_path / "f.h5").write_text("x")
    assert output_path("folder")(str(tmp_path / "d")) == str(tmp_path / "d")
    assert output_path("folder")(str(tmp_path / "new" / "deeper"))
    assert output_path("file")(str(tmp_path / "f.h5"))
    assert output_path("file")(str(tmp_path / "new" / "x.png"))
    for what, p in (("folder", tmp_path / "f.h5"), ("file", tmp_path / "d"),
                    ("file", tmp_path / "f.h5" / "x.png")):
        with pytest.raises(argparse.ArgumentTypeError):
            output_path(what)(str(p))


def _css_recording(path):
    """A minimal CSS recording (six axis-aligned sensors, 10 samples, docs/formats.md)."""
    import h5py
    import numpy as np

    normals = np.vstack([np.eye(3), -np.eye(3)])
    s = np.array([0.6, 0.8, 0.0])
    with h5py.File(path, "w") as h:
        h.attrs["format"] = "lightcurve-css"
        h["t"] = np.arange(10.0)
        h["y"] = np.tile(np.clip(normals @ s, 0, None), (10, 1))
        h["normals"] = normals
        h["fov_half_angle_rad"] = np.full(6, np.radians(80.0))


def test_batch_write_failure_recorded_and_batch_goes_on(tmp_path, capsys):
    """`r/b2.ukf.h5` is a folder: b2 is recorded as an output failure in summary.json, b1 and
    b3 are inverted and recorded; exit 1 (a run-time failure), not an abort."""
    d = tmp_path / "in"
    d.mkdir()
    for k in (1, 2, 3):
        _curve(d / f"b{k}.h5")
    out = tmp_path / "r"
    (out / "b2.ukf.h5").mkdir(parents=True)
    code, err = run_cli(["invert", d / "b1.h5", d / "b2.h5", d / "b3.h5", "-o", out,
                         "--workers", "1", "-q"], capsys)
    assert code == 1, err
    summary = json.loads((out / "summary.json").read_text())
    assert sorted(summary) == ["b1", "b2", "b3"]
    assert summary["b2"]["error_kind"] == "output" and "b2.ukf.h5" in summary["b2"]["error"]
    # the file named is the one asked for, not the (removed) temporary file beside it
    assert "Is a directory: " in summary["b2"]["error"] and ".b2.ukf.h5." not in err + \
        summary["b2"]["error"], (err, summary["b2"]["error"])
    for k in ("b1", "b3"):
        assert Path(summary[k]["result"]).is_file() and "error" not in summary[k]


def test_interrupted_batch_still_writes_the_summary(tmp_path, monkeypatch):
    """A batch interrupted (Ctrl-C, SIGTERM) after its first file writes summary.json listing
    the file finished, then lets the interruption through."""
    import lightcurve.studies.batch as batch

    files = []
    for k in (1, 2, 3):
        _curve(tmp_path / f"b{k}.h5")
        files.append(tmp_path / f"b{k}.h5")
    real_store, calls = batch._store, []

    def store_then_interrupt(*a, **kw):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real_store(*a, **kw)

    monkeypatch.setattr(batch, "_store", store_then_interrupt)
    out = tmp_path / "r"
    with pytest.raises(KeyboardInterrupt):
        batch.invert_files([str(f) for f in files], "ukf", out, workers=1, progress=False)
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary) == ["b1"] and (out / "b1.ukf.h5").is_file(), summary


def test_batch_plot_write_failure_recorded(tmp_path, capsys):
    d = tmp_path / "in"
    d.mkdir()
    for k in (1, 2):
        _curve(d / f"b{k}.h5")
    out = tmp_path / "r"
    (out / "b1.ukf.png").mkdir(parents=True)
    code, err = run_cli(["invert", d / "b1.h5", d / "b2.h5", "-o", out, "--workers", "1",
                         "--plot", "-q"], capsys)
    assert code == 1, err
    summary = json.loads((out / "summary.json").read_text())
    assert "plot_error" in summary["b1"] and Path(summary["b1"]["result"]).is_file()
    assert (out / "b2.ukf.png").is_file() and "plot_error" not in summary["b2"]


def test_batch_output_that_is_an_input_is_refused(tmp_path, capsys):
    """Inputs x.h5 and x.ukf.h5 in the output folder: x's result would replace the input
    x.ukf.h5 — x fails as bad input, x.ukf.h5 itself is inverted, nothing overwritten."""
    out = tmp_path / "r"
    out.mkdir()
    before = _curve(out / "x.ukf.h5")
    _curve(out / "x.h5")
    code, err = run_cli(["invert", out / "x.h5", out / "x.ukf.h5", "-o", out, "--workers",
                         "1", "-q"], capsys)
    assert code == 2, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["x"]["error_kind"] == "input" and "overwrite an input" in summary["x"]["error"]
    assert (out / "x.ukf.h5").read_bytes() == before
    assert Path(summary["x.ukf"]["result"]).name == "x.ukf.ukf.h5"


def _write_study(folder, runs=2):
    """The tiny two-cell study of the signal tests, ``runs`` per cell; returns its path."""
    from test_hardening_signals import SCENARIO, STUDY

    (folder / "tiny-controlled-1site.toml").write_text(SCENARIO)
    study = folder / "study.toml"
    study.write_text(STUDY.replace("runs = 2000", f"runs = {runs}"))
    return study


def test_second_run_on_a_locked_study_folder_is_refused(tmp_path, capsys):
    """While one process holds a study folder, a second `compare` on it exits 2 at once,
    naming the holder, and writes nothing."""
    from lightcurve.io.locks import folder_lock

    study = _write_study(tmp_path)
    out = tmp_path / "out"
    with folder_lock(out):
        code, err = run_cli(["compare", study, "-o", out, "--workers", "1", "-q"], capsys)
        assert code == 2 and "in use by process" in err and str(os.getpid()) in err, err
        assert not (out / "runs").exists() and not (out / "study.json").exists()
    # released: the same command now runs
    code, err = run_cli(["compare", study, "-o", out, "--workers", "1", "-q"], capsys)
    assert code == 0, err
    assert len(list((out / "runs").glob("*.h5"))) == 4


def test_lock_is_released_when_the_holder_is_killed(tmp_path):
    """flock: a SIGKILLed holder leaves no stale lock."""
    import signal

    from lightcurve.io.locks import folder_lock

    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    p = subprocess.Popen([sys.executable, "-c",
                          "import sys, time\nfrom lightcurve.io.locks import folder_lock\n"
                          "with folder_lock(sys.argv[1]):\n    print('held', flush=True)\n"
                          "    time.sleep(120)\n", str(tmp_path)], env=env,
                         stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "held"
        with pytest.raises(InputError, match="in use by process"):
            with folder_lock(tmp_path):
                pass
        p.send_signal(signal.SIGKILL)
        p.wait(30)
        with folder_lock(tmp_path):
            pass
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        p.stdout.close()


def _dead_pid():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_temp_files_removed_live_ones_kept(tmp_path):
    """Temporary files of a killed writer (same host, pid gone) are removed by the next write
    of that file and by the study start-up; a live writer's (pid alive) never; another
    host's only after a day without change."""
    from lightcurve.io.atomic import atomic_write_text, clean_stale_temp, temp_prefix

    dead = _dead_pid()
    host = temp_prefix("x").split(".")[-1].split("-")[0]
    live = os.getpid()
    names = {
        "stale": f".out.txt.{host}-{dead}-abcd1234.tmp",
        "live": f".out.txt.{host}-{live}-abcd1234.tmp",
        "foreign_new": ".out.txt.000000-1-abcd1234.tmp",
        "foreign_old": ".out.txt.000001-1-abcd1234.tmp",
        "other_file": f".else.txt.{host}-{dead}-abcd1234.tmp",
        "not_ours": ".out.txt.notatemp",
    }
    for n in names.values():
        (tmp_path / n).write_text("partial")
    old = (tmp_path / names["foreign_old"])
    os.utime(old, (old.stat().st_atime, old.stat().st_mtime - 2 * 86400))
    atomic_write_text(tmp_path / "out.txt", "done\n")
    left = {p.name for p in tmp_path.iterdir()}
    assert names["stale"] not in left and names["foreign_old"] not in left
    assert {names["live"], names["foreign_new"], names["other_file"], names["not_ours"],
            "out.txt"} <= left
    assert clean_stale_temp(tmp_path) == 1  # the folder-wide clean-up takes other_file
    assert names["live"] in {p.name for p in tmp_path.iterdir()}


def test_study_startup_keeps_a_live_writers_temp_file(tmp_path):
    """prepare_output used to delete every `.*.h5.*` in runs/, a live writer's included."""
    from lightcurve.io.atomic import temp_prefix
    from lightcurve.studies.runner import prepare_output
    from lightcurve.studies.study import load_study

    _write_study(tmp_path)
    runs = tmp_path / "out" / "runs"
    runs.mkdir(parents=True)
    live = runs / (temp_prefix("abc_r00000.h5") + "abcd1234.tmp")
    dead = runs / (temp_prefix("abc_r00001.h5").replace(f"-{os.getpid()}-", f"-{_dead_pid()}-")
                   + "abcd1234.tmp")
    live.write_text("x")
    dead.write_text("x")
    prepare_output(tmp_path / "out", load_study(tmp_path / "study.toml"))
    assert live.exists() and not dead.exists()


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_written_files_follow_the_umask(tmp_path, umask, mode):
    """Every output used to be 0600 (the temporary file's mode) whatever the umask."""
    from lightcurve.io.atomic import atomic_write_text

    old = os.umask(umask)
    try:
        atomic_write_text(tmp_path / "a.txt", "x")
        small_curve().write(tmp_path / "c.h5")
    finally:
        os.umask(old)
    for f in ("a.txt", "c.h5"):
        assert (tmp_path / f).stat().st_mode & 0o777 == mode, f


def test_every_write_checks_the_inputs_read(tmp_path):
    """Inside the command line (track_inputs), any atomic write over a file that was read as
    an input is refused, whichever command or code path writes it; outside, the library
    may rewrite a file it read (read, change, write back)."""
    from lightcurve.io.lightcurve_h5 import read_lightcurve
    from lightcurve.io.safe_open import track_inputs

    p = tmp_path / "lc.h5"
    before = _curve(p)
    lc = read_lightcurve(p)
    lc.write(p)  # library use: allowed
    with track_inputs():
        lc = read_lightcurve(p)
        before = p.read_bytes()
        with pytest.raises(InputError, match="overwrite an input"):
            lc.write(p)
        lc.write(tmp_path / "other.h5")
    assert p.read_bytes() == before
