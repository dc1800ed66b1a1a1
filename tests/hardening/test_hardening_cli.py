"""CLI exit codes and error lines: 0 success, 1 run-time failure, 2 bad usage or bad input
(docs/robustness.md "CLI exit codes"); an error prints ONE line on stderr (``lightcurve: error:
...`` / ``lightcurve: failed: ...``), the traceback only with ``--debug``. Output names derived
from data stay inside the output folder (lightcurve.io.paths.safe_output_path).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardening_util import fuzz_settings, small_curve
from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.cli import main
from lightcurve.io.paths import safe_name, safe_output_path

REPO = Path(__file__).resolve().parents[2]


def run(argv, capsys):
    """main(argv) -> (exit code, stdout, stderr); argparse usage errors become exit code 2."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: usage error (2) or --help (0)
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def one_error_line(err: str, kind="error") -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected one line on stderr, got:\n{err}"
    assert lines[0].startswith(f"lightcurve: {kind}:"), lines[0]
    assert "Traceback" not in err
    return lines[0]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    good = d / "good.h5"
    small_curve().write(good)
    corrupt = d / "corrupt.h5"
    corrupt.write_bytes(good.read_bytes()[:700])
    bad_toml = d / "bad.toml"
    bad_toml.write_text("[scenario]\nname = \n")
    empty_dir = d / "empty"
    empty_dir.mkdir()
    return {"dir": d, "good": good, "corrupt": corrupt, "bad_toml": bad_toml, "empty": empty_dir}


# ----------------------------------------------------------------------------------------
# usage errors: exit 2 (argparse)
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv", [
    [], ["no-such-command"], ["simulate"], ["simulate", "x.toml"], ["sites"], ["shapes"], ["css"],
    ["simulate", "x.toml", "-o", "y.h5", "--seed", "-1"],
    ["simulate", "x.toml", "-o", "y.h5", "--seed", "abc"],
    ["css", "simulate", "--dt-s", "0"], ["css", "simulate", "--duration-s", "nan"],
    ["css", "simulate", "--fov-deg", "91"], ["css", "study", "x.toml", "--runs", "0"],
    ["css", "estimate", "x.h5", "--estimator", "magic"], ["invert", "x.h5"],
    ["invert", "x.h5", "-o", "d", "--particles", "0"], ["invert", "x.h5", "-o", "d", "--alpha", "nan"],
    ["invert", "x.h5", "-o", "d", "--ess-threshold", "2"], ["diagnose", "x.h5"],
    ["diagnose", "x.h5", "-o", "d", "--max-effects", "3"],
])
def test_usage_errors_exit_2(argv, capsys):
    code, _, _ = run(argv, capsys)
    assert code == 2


# ----------------------------------------------------------------------------------------
# bad input: exit 2, one line naming the file
# ----------------------------------------------------------------------------------------
BAD_INPUT = [
    (["sites", "show", "atlantis"], "unknown site"),
    (["sites", "list", "--sites", "{missing}"], "site folder not found"),
    (["shapes", "show", "no_such_shape"], "unknown shape"),
    (["shapes", "--library", "{missing}", "list"], "shape library folder not found"),
    (["simulate", "{bad_toml}", "-o", "{dir}/o.h5"], "bad.toml"),
    (["simulate", "{missing}.toml", "-o", "{dir}/o.h5"], "file not found"),
    (["plot", "{corrupt}"], "corrupt.h5"),
    (["plot", "{bad_toml}"], "bad.toml"),
    (["demo", "--scenario", "{bad_toml}", "-o", "{dir}/demo"], "bad.toml"),
    (["css", "estimate", "{corrupt}"], "corrupt.h5"),
    (["css", "estimate", "{good}"], "not a CSS recording"),
    (["css", "study", "{bad_toml}"], "bad.toml"),
    (["css", "simulate", "--duration-s", "10", "--albedo", "{bad_toml}"], "bad.toml"),
    (["css", "simulate", "--duration-s", "10", "--config", "{bad_toml}"], "bad.toml"),
    (["css", "simulate", "--duration-s", "10", "--epoch", "2020-02-30"], "epoch_utc"),
    (["invert", "{corrupt}", "-o", "{dir}/inv"], "corrupt.h5"),
    (["diagnose", "{corrupt}", "-o", "{dir}/dg"], "corrupt.h5"),
    (["diagnose", "{bad_toml}", "-o", "{dir}/dg"], "bad.toml"),
]


@pytest.mark.parametrize("argv, frag", BAD_INPUT)
def test_bad_input_exit_2_one_line(argv, frag, files, capsys):
    fmt = {**{k: str(v) for k, v in files.items()}, "missing": str(files["dir"] / "missing")}
    code, _, err = run([a.format(**fmt) for a in argv], capsys)
    assert code == 2, err
    assert frag in one_error_line(err)


def test_shapes_validate_problems_exit_2(files, capsys):
    code, out, _ = run(["shapes", "validate", str(files["bad_toml"])], capsys)
    assert code == 2 and "bad.toml" in out


# ----------------------------------------------------------------------------------------
# run-time failure: exit 1, one line; success: exit 0
# ----------------------------------------------------------------------------------------
def test_runtime_failure_exit_1_one_line(files, capsys, tmp_path, monkeypatch):
    """A write that fails at run time (here: the disk is full when the PNG is stored) is
    exit 1 with one line. (An output path of the wrong kind is caught at parse time, exit 2.)"""
    import contextlib
    import errno

    import lightcurve.report.plot_any as plot_any
    import lightcurve.report.plots as plots

    @contextlib.contextmanager
    def disk_full(path, suffix=None):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))
        yield  # pragma: no cover

    monkeypatch.setattr(plot_any, "atomic_path", disk_full)
    monkeypatch.setattr(plots, "atomic_path", disk_full)
    code, _, err = run(["plot", str(files["good"]), "-o", str(tmp_path / "x.png")], capsys)
    assert code == 1
    assert "No space left on device" in err
    line = one_error_line(err, kind="failed")
    assert "--debug" in line


def test_success_exit_0(files, capsys):
    code, out, err = run(["sites", "show", "socorro"], capsys)
    assert code == 0 and "33.8173" in out and err == ""
    code, out, _ = run(["plot", str(files["good"]), "-o", str(files["dir"] / "ok.png")], capsys)
    assert code == 0 and (files["dir"] / "ok.png").stat().st_size > 1000


def test_debug_prints_traceback_and_keeps_exit_code(files, capsys):
    code, _, err = run(["--debug", "plot", str(files["corrupt"])], capsys)
    assert code == 2
    assert "Traceback" in err and err.strip().splitlines()[-1].startswith("lightcurve: error:")


def test_multiline_messages_folded_to_one_line(capsys, monkeypatch):
    import lightcurve.cli as cli

    def boom(args):
        raise InputError("first line\nsecond line", file="f.toml")

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    parser._subparsers._group_actions[0].choices["selfcheck"].set_defaults(func=boom)
    code, _, err = run(["selfcheck"], capsys)
    assert code == 2 and "first line second line" in one_error_line(err)


def test_python_dash_m_subprocess_exit_codes(files):
    """The real entry point: `python -m lightcurve` returns the codes to the shell."""
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run([sys.executable, "-m", "lightcurve", "plot", str(files["corrupt"])],
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    r = subprocess.run([sys.executable, "-m", "lightcurve", "sites", "show", "socorro"],
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0 and "socorro" in r.stdout


# ----------------------------------------------------------------------------------------
# output paths derived from data stay inside the output folder
# ----------------------------------------------------------------------------------------
@fuzz_settings(300)
@given(st.one_of(st.text(max_size=60), st.sampled_from(["..", "../x", "/etc/passwd", "a/../../b", "\\..\\x",
                                                         "C:\\Windows\\x", "~root", "\x00", ".", " ",
                                                         "名前/../..", "CON", "x" * 400])))
def test_safe_output_path_never_escapes(name):
    out = Path("/tmp/lc-out-folder")
    try:
        p = safe_output_path(out, name, ".h5")
    except InputError:
        return
    assert p.parent == out and p.name.endswith(".h5") and not p.name.startswith(".")
    assert "/" not in p.name and "\\" not in p.name and "\x00" not in p.name
    assert len(p.name.encode()) <= 255 and safe_name(name) + ".h5" == p.name


def test_safe_output_path_rejects_bad_suffix():
    with pytest.raises(ValueError):
        safe_output_path("/tmp", "x", "/../y")


def test_demo_scenario_name_cannot_escape_output_folder(tmp_path, capsys):
    """A scenario named '../../escaped' writes into OUT, not two folders up."""
    text = (data_dir("pipelines") / "default.toml").read_text()
    text = text.replace('name = "cubesat-pass-socorro"', 'name = "../../escaped"')
    scen = tmp_path / "s.toml"
    scen.write_text(text)
    out = tmp_path / "a" / "b" / "out"
    code, stdout, err = run(["demo", "--scenario", str(scen), "-o", str(out)], capsys)
    assert code == 0, err
    assert (out / "escaped.h5").is_file() and (out / "escaped.png").is_file()
    assert not (tmp_path / "a" / "escaped.h5").exists()
