"""One command line: every (sub)command answers --help, every option is explained, shared
options are spelled one way everywhere, --version prints the package version, and an option
the chosen method ignores is refused (exit 2) instead of silently dropped."""

from __future__ import annotations

import argparse
import io
import re
import tomllib
from contextlib import redirect_stdout
from pathlib import Path

import pytest

import lightcurve
from lightcurve.cli import build_parser, iter_commands, main
from lightcurve.cli._args import SHARED_OPTIONS

ROOT = Path(__file__).resolve().parents[2]
COMMANDS = list(iter_commands())
# spellings that must not come back (the canonical one in brackets)
FORBIDDEN = {"--out": "-o/--output", "--outdir": "-o/--output", "--output-dir": "-o/--output",
             "--n-workers": "--workers", "--nworkers": "--workers", "--jobs": "--workers",
             "--random-seed": "--seed", "--rng-seed": "--seed", "--lib": "--library",
             "--shape-library": "--library", "--site-dir": "--sites", "--observatories": "--sites",
             "--silent": "-q/--quiet", "--no-progress": "-q/--quiet", "--dask": "--dask-local",
             "--dask-scheduler": "--scheduler"}


def _options(parser):
    for a in parser._actions:
        if a.option_strings and not isinstance(a, (argparse._HelpAction,
                                                   argparse._SubParsersAction)):
            yield a


def test_command_tree_is_complete():
    names = {" ".join(w) for w, _ in COMMANDS}
    assert {"demo", "simulate", "plot", "invert", "compare", "diagnose", "fit-reflection",
            "sites list", "shapes list", "selfcheck", "warmup", "css simulate",
            "css study", "css faults", "css vmm", "import", "passes", "period"} <= names


@pytest.mark.parametrize("words", [w for w, _ in COMMANDS], ids=[" ".join(w) for w, _ in COMMANDS])
def test_every_command_accepts_help(words):
    buf = io.StringIO()
    with redirect_stdout(buf), pytest.raises(SystemExit) as exc:
        main(list(words) + ["--help"])
    assert exc.value.code == 0
    text = buf.getvalue()
    assert text.startswith("usage: lightcurve " + " ".join(words))
    assert "%%" not in text and "%(" not in text   # argparse escapes rendered


def test_every_option_has_help_and_no_variant_spellings():
    problems = []
    for words, p in [((), build_parser())] + COMMANDS:
        where = "lightcurve " + " ".join(words)
        for a in _options(p):
            if a.help == argparse.SUPPRESS:  # a hidden alias must map to the canonical option
                alias_of = {"--out": "output"}
                if not all(alias_of.get(o) == a.dest for o in a.option_strings):
                    problems.append(f"{where}: hidden option {a.option_strings} is not an alias")
                continue
            if not (a.help and a.help.strip()):
                problems.append(f"{where}: {'/'.join(a.option_strings)} has no help text")
            for o in a.option_strings:
                if o in FORBIDDEN:
                    problems.append(f"{where}: {o} should be spelled {FORBIDDEN[o]}")
    assert problems == []


def test_shared_options_are_spelled_the_same_everywhere():
    problems = []
    canon = {flag: dest for dest, (flags, _) in SHARED_OPTIONS.items() for flag in flags}
    for words, p in COMMANDS:
        where = "lightcurve " + " ".join(words)
        for a in _options(p):
            if a.help == argparse.SUPPRESS:
                continue
            shared = {canon[o] for o in a.option_strings if o in canon}
            if a.dest in SHARED_OPTIONS or shared:
                key = a.dest if a.dest in SHARED_OPTIONS else sorted(shared)[0]
                flags, meta = SHARED_OPTIONS[key]
                if key in ("quiet", "plot") and not isinstance(a, argparse._StoreTrueAction):
                    problems.append(f"{where}: {flags[-1]} must be a flag (takes no value)")
                if tuple(a.option_strings) != flags:
                    problems.append(f"{where}: dest {a.dest!r} spelled {a.option_strings}, "
                                    f"expected {list(flags)}")
                if meta is not None and a.metavar != meta:
                    problems.append(f"{where}: {flags[-1]} metavar {a.metavar!r}, expected {meta!r}")
    assert problems == []


def test_version_prints_the_package_version(capsys):
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert lightcurve.__version__ == version
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"lightcurve {version}"


@pytest.mark.parametrize("argv, frag", [
    (["--particles", "500", "--method", "ukf"], "--particles does not apply to --method ukf"),
    (["--alpha", "0.5", "--method", "mekf"], "--alpha does not apply to --method mekf"),
    (["--roughening", "0.3", "--method", "ukf"], "--roughening does not apply"),
])
def test_inapplicable_options_are_refused(argv, frag, tmp_path, capsys):
    import warnings

    from lightcurve._paths import data_dir

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f = lightcurve.simulate(data_dir("pipelines") / "default.toml").write(tmp_path / "c.h5")
    code = main(["invert", str(f), "-o", str(tmp_path / "o")] + argv)
    assert code == 2
    err = capsys.readouterr().err
    assert frag in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_typed_options_are_told_from_defaults(tmp_path):
    """--particles 10000 (the default value, but typed) is still refused with --method ukf."""
    from lightcurve.cli import _typed_options

    p = build_parser()
    assert "particles" in _typed_options(p, ["invert", "x.h5", "-o", "o", "--particles", "10000"])
    assert "particles" not in _typed_options(p, ["invert", "x.h5", "-o", "o"])


def test_help_lines_do_not_leak_defaults_as_python_reprs():
    for words, p in COMMANDS:
        text = p.format_help()
        assert not re.search(r"default: None\b|\(default None\)", text), words


def test_help_and_parsing_import_no_numerical_stack():
    """`lightcurve --help`, `sites list` … start fast: building the parser imports neither numba,
    scipy, matplotlib nor h5py (the handlers import what they need)."""
    import subprocess
    import sys

    code = ("import sys, lightcurve.cli as c; c.build_parser(); "
            "print(sorted(m for m in ('numba', 'scipy', 'matplotlib', 'h5py', 'skyfield') "
            "if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"
