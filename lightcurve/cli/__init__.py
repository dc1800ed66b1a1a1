"""The ``lightcurve`` command line.

One module per subcommand group (``sites``, ``shapes``, ``simulate``/``plot``/``demo``, ``css``,
``invert``, ``diagnose``, ``compare``, ``fit-reflection``, ``import``/``passes``,
``selfcheck``); each has a ``register(subparsers)`` function and thin handlers that parse
arguments, call the library and print. Shared option types live in
:mod:`lightcurve.cli._args`. Exit codes: 0 success, 1 run-time failure, 2 bad usage or bad
input (one clear line; the traceback only with ``--debug``), 130 / 143 / 129 interrupted by
SIGINT / SIGTERM / SIGHUP (stored results kept; one line saying how to resume,
:mod:`lightcurve.process`). Every command runs with its inputs tracked
(:func:`lightcurve.io.safe_open.track_inputs`): an output that would replace one of its inputs
is refused (exit 2).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import traceback

from ..errors import InputError
from . import (
    compare,
    css,
    diagnose,
    invert,
    period,
    recordings,
    reflection,
    selfcheck,
    shapes,
    simulate,
    sites,
)

__all__ = ["main", "build_parser", "iter_commands"]

_REGISTRARS = (selfcheck.register, sites.register, shapes.register, simulate.register,
               css.register, invert.register, period.register, diagnose.register,
               compare.register, reflection.register, recordings.register)


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every registered subcommand.

    ``--plugin MODULE`` and ``--debug`` are accepted before the command and after it (they are
    added to every subcommand's parser), so ``lightcurve simulate s.toml --plugin mybrdf``
    works as well as ``lightcurve --plugin mybrdf simulate s.toml``.
    """
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="lightcurve",
        description="Simulate and invert photometric lightcurves of spacecraft; coarse sun "
        "sensor estimation. Run 'lightcurve COMMAND --help' for each command.",
    )
    parser.add_argument("--version", action="version", version=f"lightcurve {__version__}",
                        help="print the package version and exit")
    _add_global_options(parser, top=True)
    sub = parser.add_subparsers(title="commands", metavar="COMMAND")
    for reg in _REGISTRARS:
        reg(sub)
    for p in _leaf_parsers(parser):
        if p is not parser:
            _add_global_options(p, top=False)
    return parser


def _add_global_options(p, top):
    """``--plugin`` (repeatable) and ``--debug``; subcommand copies keep the top-level values."""
    dflt = [] if top else argparse.SUPPRESS
    p.add_argument("--plugin", action="append", default=dflt, metavar="MODULE",
                   dest="plugin" if top else "plugin_sub",
                   help="import a user module first (a module name or a .py file) that "
                   "registers BRDFs or physics effects, or lists shape folders in SHAPE_DIRS "
                   "(repeatable; docs/extending.md)")
    p.add_argument("--debug", action="store_true",
                   default=False if top else argparse.SUPPRESS,
                   help="print full tracebacks on errors")


def _subparsers(parser):
    for a in parser._actions:  # argparse keeps sub-parsers on the _SubParsersAction
        if isinstance(a, argparse._SubParsersAction):
            seen = set()
            for name, p in a.choices.items():
                if id(p) not in seen:
                    seen.add(id(p))
                    yield name, p


def _leaf_parsers(parser):
    """Every parser in the tree (the root included), depth first."""
    yield parser
    for _, p in _subparsers(parser):
        yield from _leaf_parsers(p)


def iter_commands(parser=None, prefix=()):
    """``(command words, parser)`` for every (sub)command, e.g. ``(("css", "study"), p)``."""
    parser = parser or build_parser()
    for name, p in _subparsers(parser):
        yield prefix + (name,), p
        yield from iter_commands(p, prefix + (name,))


def _typed_options(parser, argv) -> set:
    """The dests of the options typed in ``argv`` (defaults suppressed and parsed again)."""
    saved = []
    for p in _leaf_parsers(parser):
        for a in p._actions:
            saved.append((a, a.default))
            a.default = argparse.SUPPRESS
        saved.append((p, dict(p._defaults)))
        p._defaults = {k: v for k, v in p._defaults.items() if k == "func"}
    try:
        ns, _ = parser.parse_known_args(argv)
        return set(vars(ns)) - {"func"}
    except SystemExit:
        return set()
    finally:
        for obj, val in saved:
            if isinstance(obj, argparse.ArgumentParser):
                obj._defaults = val
            else:
                obj.default = val


def main(argv=None) -> int:
    """Entry point of the ``lightcurve`` console script; returns the exit code."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    args.plugin = list(args.plugin) + list(getattr(args, "plugin_sub", []))
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    args._given = _typed_options(parser, argv)
    from ..io.safe_open import track_inputs
    from ..process import Terminated, exit_code, handle_termination

    try:
        with handle_termination(), track_inputs(), _one_line_warnings():
            from ..plugins import load_plugin

            for spec in args.plugin:
                load_plugin(spec)
            return int(args.func(args) or 0)
    except InputError as exc:  # bad input: exit 2
        if args.debug:
            traceback.print_exc()
        print(f"lightcurve: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM, SIGHUP (lightcurve.process)
        if args.debug:
            traceback.print_exc()
        how = f"terminated by {exc.name}" if isinstance(exc, Terminated) else "interrupted"
        hint = getattr(args, "resume_hint", None)
        hint = "" if not hint else "; " + hint.format(**vars(args))
        print(f"lightcurve: {how}{hint}", file=sys.stderr)
        return exit_code(exc)
    except BrokenPipeError:  # `lightcurve ... | head`: the reader went away, not our failure
        try:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115  silence the flush at exit
        except OSError:
            pass
        return 0
    except Exception as exc:  # run-time failure: exit 1, one line unless --debug
        if args.debug:
            traceback.print_exc()
        hint = "" if args.debug else " (run with --debug for details)"
        print(f"lightcurve: failed: {type(exc).__name__}: {_one_line(exc)}{hint}", file=sys.stderr)
        return 1


#: NumPy's floating-point chatter (results carry their own NaN/flag checks)
_NUMPY_FP = r"(invalid value|divide by zero|overflow|underflow) encountered|Mean of empty slice"


@contextlib.contextmanager
def _one_line_warnings():
    """Warnings of a command as one ``lightcurve: warning: ...`` line each (no source line,
    no file path of the package); NumPy floating-point chatter is not shown."""
    import warnings

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"lightcurve: warning: {_one_line(message)}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=_NUMPY_FP, category=RuntimeWarning)
        warnings.showwarning = show
        yield


def _one_line(exc: BaseException, limit: int = 2000) -> str:
    """The exception's text on one line (newlines folded), at most ``limit`` characters."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
