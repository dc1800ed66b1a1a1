"""Shared argument types and option spellings of the ``lightcurve`` command line.

Every subcommand builds its options from these helpers so that one option is spelled one way
everywhere (``-o/--output``, ``--library``, ``--sites``, ``--seed``, ``--workers``); a bad number
is a usage error (exit 2) at parse time, never a crash later on.
"""

from __future__ import annotations

import argparse
import inspect
import sys

import numpy as np

from ..errors import InputError

__all__ = ["number", "SEED", "csv_list", "csv_ints", "output_not_input", "naming_file",
           "output_path", "csv_floats", "initial_q", "initial_omega_rad_s", "SHARED_OPTIONS", "add_output",
           "add_library", "add_sites", "add_shape", "add_model_options", "add_seed",
           "add_executors", "add_workers", "add_quiet", "add_plot", "add_variant", "add_device",
           "given", "refuse_inapplicable", "progress_bar", "add_command", "add_group",
           "report_written"]


def number(lo=None, hi=None, *, lo_open=False, hi_open=False, integer=False):
    """argparse ``type=`` for a finite number in [lo, hi] (open ends with ``*_open``)."""

    def conv(text):
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if integer else 'a number'}, got {text!r}") from None
        if not np.isfinite(v):
            raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
        if (lo is not None and (v < lo or (lo_open and v == lo))) or \
                (hi is not None and (v > hi or (hi_open and v == hi))):
            rng = (f"{'(' if lo_open else '['}{'-inf' if lo is None else lo}, "
                   f"{'inf' if hi is None else hi}{')' if hi_open else ']'}")
            raise argparse.ArgumentTypeError(f"{text} is out of range; allowed: {rng}")
        return v

    conv.__name__ = "integer" if integer else "number"
    return conv


SEED = number(0, 2**63 - 1, integer=True)


def csv_list(text, option):
    """Split a comma-separated CLI value into stripped, non-empty items (InputError if none)."""
    items = tuple(x.strip() for x in str(text).split(",") if x.strip())
    if not items:
        raise InputError("needs at least one comma-separated value", field=option,
                         value=text)
    return items


def csv_ints(text, option):
    """Comma-separated non-negative integers (facet indices) from a CLI value."""
    out = []
    for x in csv_list(text, option):
        try:
            v = int(x)
        except ValueError:
            v = -1
        if v < 0 or str(v) != x.lstrip("+"):
            raise InputError("not a non-negative integer", field=option, value=x,
                             allowed="0-based facet indices, e.g. 0,2,5")
        out.append(v)
    return tuple(out)



def output_not_input(output, *inputs, option: str = "-o/--output") -> None:
    """Refuse (InputError, exit 2) an output file that names one of the command's inputs —
    the same file by device and inode (links count) or the same absolute path — before any
    work is done. (Writes are checked again when they happen:
    :func:`lightcurve.io.safe_open.check_not_input`.)"""
    import os

    if output is None:
        return
    for inp in inputs:
        if inp is None:
            continue
        try:
            same = os.path.samefile(output, inp)
        except (OSError, ValueError):
            same = os.path.abspath(output) == os.path.abspath(inp)
        if same:
            raise InputError("the output would overwrite an input file of this command",
                             file=output, field=option, value=str(inp),
                             allowed="an output path that is not one of the inputs")


class naming_file:  # noqa: N801 - used as a context manager: ``with naming_file(path):``
    """Re-raise an :class:`InputError` that names no file as one naming ``path`` (the input
    the command was working on), so every error line says which file it is about."""

    def __init__(self, path):
        self.path = path

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        if isinstance(exc, InputError) and not exc.file and self.path is not None:
            raise InputError(exc.bare_message, file=self.path, field=exc.field,
                             value=exc.value, allowed=exc.allowed) from None
        return False


def csv_floats(text, option, n=None):
    """Comma-separated finite numbers from a CLI value (exactly ``n`` when given)."""
    out = []
    for x in csv_list(text, option):
        try:
            v = float(x)
        except ValueError:
            v = float("nan")
        if not np.isfinite(v):
            raise InputError("not a finite number", field=option, value=x)
        out.append(v)
    if n is not None and len(out) != n:
        raise InputError(f"expected {n} comma-separated numbers", field=option, value=text)
    return tuple(out)


def initial_q(text, option="--initial-q"):
    """A unit quaternion ``q1,q2,q3,q4`` (scalar first, inertial→body) from the CLI.

    Values whose norm is within 1e-3 of one are normalised (four typed decimals are rarely
    exactly unit); anything else is refused.
    """
    q = np.asarray(csv_floats(text, option, 4))
    nq = float(np.linalg.norm(q))
    if abs(nq - 1.0) > 1e-3:
        raise InputError("not a unit quaternion", field=option, value=text,
                         allowed="q1,q2,q3,q4 (scalar first) with norm 1 (to 1e-3)")
    return tuple(float(x) for x in q / nq)


def initial_omega_rad_s(text, option="--initial-omega-deg-s"):
    """A body rate ``wx,wy,wz`` given in deg/s on the CLI, returned in rad/s."""
    w = np.radians(csv_floats(text, option, 3))
    if np.any(np.abs(w) > np.radians(3600.0)):
        raise InputError("body rate out of range", field=option, value=text,
                         allowed="|w| <= 3600 deg/s per axis")
    return tuple(float(x) for x in w)


# ------------------------------------------------------------------------------------------
# One spelling per shared option. Subcommands add these with the helpers below (never by
# hand) so that `tests/cli/test_cli_consistency.py` finds each option spelled and explained
# the same way everywhere.

#: The shared options: dest -> (flags, metavar). The consistency test checks every parser.
SHARED_OPTIONS = {
    "output": (("-o", "--output"), None),
    "library": (("--library",), "DIR"),
    "sites": (("--sites",), "DIR"),
    "seed": (("--seed",), "SEED"),
    "workers": (("--workers",), "N"),
    "dask_local": (("--dask-local",), "W"),
    "scheduler": (("--scheduler",), "ADDRESS"),
    "variant": (("--variant",), None),
    "device": (("--device",), None),
    "quiet": (("-q", "--quiet"), None),
    "plot": (("--plot",), None),
}


def output_path(what="folder"):
    """argparse ``type=`` of ``-o/--output``: a path that can become the output ``what``
    ("folder" or "file"), checked before any work (usage error, exit 2): a folder output may
    not be an existing non-folder, a file output may not be an existing folder, and the
    nearest existing parent must be a folder (``-o report.txt/x.h5`` would fail only when the
    result is written, after the whole run)."""
    import os

    def conv(text):
        path = os.path.abspath(text)
        if what == "folder" and os.path.exists(path) and not os.path.isdir(path):
            raise argparse.ArgumentTypeError(f"{text!r} exists and is not a folder; allowed: "
                                             "an existing folder or a new path")
        if what == "file" and os.path.isdir(path):
            raise argparse.ArgumentTypeError(f"{text!r} is a folder; allowed: a file path "
                                             "(existing files are replaced)")
        parent = os.path.dirname(path)
        while parent and not os.path.lexists(parent) and os.path.dirname(parent) != parent:
            parent = os.path.dirname(parent)
        if os.path.lexists(parent) and not os.path.isdir(parent):
            raise argparse.ArgumentTypeError(f"{text!r}: {parent!r} is not a folder; allowed: "
                                             "a path whose parents are folders")
        return text

    conv.__name__ = f"output {what}"
    return conv


def add_output(p, *, what="folder", required=False, default=None, help=None):
    """``-o/--output`` (``what`` = "folder" or "file"); ``help`` describes what goes there.
    The path is checked at parse time (:func:`output_path`)."""
    meta = "DIR" if what == "folder" else "FILE"
    text = help or ("output folder" if what == "folder" else "output file")
    if default is not None and "default" not in text:
        text += f" (default: {default})"
    return p.add_argument("-o", "--output", metavar=meta, required=required, default=default,
                          type=output_path(what), help=text)


def add_library(p):
    """``--library DIR`` (repeatable): extra shape folders searched before the bundled ones."""
    return p.add_argument("--library", action="append", default=None, metavar="DIR",
                          help="extra shape library folder, searched before the bundled "
                          "shapes/ (repeatable)")


def add_sites(p):
    """``--sites DIR`` (repeatable): extra observatory folders."""
    return p.add_argument("--sites", action="append", default=None, metavar="DIR",
                          help="extra folder of observatory TOML files (repeatable; later "
                          "folders override earlier ones)")


def add_seed(p, default=0, help=None):
    """``--seed SEED`` (non-negative integer)."""
    text = help or "random seed"
    text += " (default: the scenario's)" if default is None else f" (default {default})"
    return p.add_argument("--seed", type=SEED, default=default, metavar="SEED", help=text)


def add_executors(p, *, workers_help=None):
    """``--workers N`` | ``--dask-local W`` | ``--scheduler ADDRESS`` (mutually exclusive)."""
    ex = p.add_mutually_exclusive_group()
    ex.add_argument("--workers", type=number(1, 4096, integer=True), default=None, metavar="N",
                    help=workers_help or "local process-pool size (default: one per CPU; 1 "
                    "runs in this process)")
    ex.add_argument("--scheduler", metavar="ADDRESS", default=None,
                    help="address of an existing Dask scheduler, e.g. tcp://10.0.0.5:8786. "
                    "Dask sends tasks and results as pickles: whoever controls the scheduler "
                    "or a worker can run code in this process. Use only a cluster you control "
                    "(docs/robustness.md)")
    ex.add_argument("--dask-local", type=number(1, 4096, integer=True), default=None,
                    metavar="W", help="start a Dask LocalCluster with W worker processes")
    return ex


def add_workers(p, default=None, help=None):
    """``--workers N`` alone (commands without the Dask executors)."""
    return p.add_argument("--workers", type=number(1, 4096, integer=True), default=default,
                          metavar="N", help=help or "local worker processes (default: "
                          + ("one per CPU" if default is None else str(default)) + ")")


def add_quiet(p, help="no progress bar or progress messages"):
    """``-q/--quiet``."""
    return p.add_argument("-q", "--quiet", action="store_true", help=help)


def add_plot(p, help="also write PNG figures next to the outputs"):
    """``--plot`` (a flag; commands whose figure needs a path take ``--plot`` plus ``-o``)."""
    return p.add_argument("--plot", action="store_true", help=help)


def add_variant(p, default="robust"):
    """``--variant {thesis,robust}``: the source's algorithm or our improved one."""
    dflt = ("the input's own setting (a lightcurve's stored scenario [filter] variant), "
            "else robust") if default is None else default
    return p.add_argument("--variant", choices=("thesis", "robust"), default=default,
                          help="thesis: the source text's algorithm exactly; robust: the "
                          f"improved default (default {dflt})")


def add_device(p, default="cpu"):
    """``--device {cpu,gpu}``."""
    return p.add_argument("--device", choices=("cpu", "gpu"), default=default,
                          help=f"where the particle kernels run (default {default})")


# ------------------------------------------------------------------------------------------
# Options that do not apply to the chosen method are refused (exit 2), never silently ignored.

def given(args, dest) -> bool:
    """True when option ``dest`` was typed on the command line (not just defaulted).

    ``lightcurve.cli.main`` stores the set of typed options in ``args._given``; without it
    (a handler called directly) an option counts as given when it differs from None/False.
    """
    g = getattr(args, "_given", None)
    if g is not None:
        return dest in g
    v = getattr(args, dest, None)
    return v is not None and v is not False


def refuse_inapplicable(args, selector, rules):
    """Raise :class:`InputError` when an option was given that the chosen method ignores.

    ``selector`` is the dest that chooses (``"method"``); ``rules`` maps an option's dest to
    the values of ``selector`` it applies to, e.g. ``{"particles": {"bpf"}}``.
    """
    chosen = getattr(args, selector)
    flag = "--" + selector.replace("_", "-")
    for dest, allowed in rules.items():
        if chosen not in allowed and given(args, dest):
            opt = "--" + dest.replace("_", "-")
            raise InputError(
                f"{opt} does not apply to {flag} {chosen}", field=opt,
                allowed=f"{flag} {' or '.join(sorted(allowed))}")


def progress_bar(total=None, desc=None, quiet=False, unit="it"):
    """A tqdm progress bar on stderr (disabled by ``--quiet``). Use as a context manager."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, disable=bool(quiet), file=sys.stderr, unit=unit,
                dynamic_ncols=True, leave=False)


def add_command(sub, name, func, *, help, description=None, **defaults):
    """The subcommand ``name`` of the subparsers ``sub``, run by ``func(args) -> exit status``:
    its parser, with ``help`` (its line in the command list) and ``description`` (its
    ``--help`` text; default: the handler's docstring, so the command is described in one
    place), and ``func`` stored as ``args.func`` (with ``defaults``, e.g. the ``resume_hint``
    printed on interruption). Returns the parser for the command's options."""
    if description is None and func.__doc__:
        description = inspect.cleandoc(func.__doc__)
    p = sub.add_parser(name, help=help, description=description)
    p.set_defaults(func=func, **defaults)
    return p


def report_written(*paths, detail="") -> int:
    """Print the line a command ends with, ``wrote A``, ``wrote A and B`` or ``wrote A, B and
    C`` followed by ``detail``, and return the success exit status 0 (``return
    report_written(...)`` ends a handler)."""
    names = [str(p) for p in paths]
    listed = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
    print(f"wrote {listed}{detail}")
    return 0


def add_group(sub, name, *, title, metavar, help, description):
    """A command group ``name`` with its own actions: returns ``(parser, actions)`` (the
    subparsers to add the actions to); the group alone prints its help and exits 2."""
    p = add_command(sub, name, lambda args: (p.print_help(), 2)[1], help=help,
                    description=description)
    actions = p.add_subparsers(title=title, metavar=metavar)
    return p, actions


def add_shape(p):
    """``--shape NAME|FILE.toml``: a shape replacing the one a lightcurve file carries."""
    return p.add_argument("--shape", default=None, metavar="NAME|FILE.toml",
                          help="shape to model with instead of the one the file carries (a "
                          "library name, looked up in --library folders first, or a shape TOML)")


def add_model_options(p, *, shape=True, library=True, sites=True) -> None:
    """The model-input options ``--shape``, ``--library``, ``--sites`` (values land in
    ``args.shape``, ``args.library``, ``args.sites``), spelled as everywhere else."""
    if shape:
        add_shape(p)
    if library:
        add_library(p)
    if sites:
        add_sites(p)
