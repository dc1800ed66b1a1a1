"""The ``lightcurve`` command line.

One module per subcommand group (``sites``, ``shapes``, ``simulate``/``plot``/``demo``, ``css``,
``invert``, ``diagnose``, ``compare``, ``fit-reflection``, ``selfcheck``); each has a
``register(subparsers)`` function and thin handlers that parse arguments, call the library and
print. Shared option types live in :mod:`lightcurve.cli._args`. Exit codes: 0 success,
1 run-time failure, 2 bad usage or bad input (one clear line; the traceback only with
``--debug``), 130 / 143 / 129 interrupted by SIGINT / SIGTERM / SIGHUP (stored results kept;
one line saying how to resume, :mod:`lightcurve.process`). Every command runs with its
inputs tracked (:func:`lightcurve.io.safe_open.track_inputs`): an output that would replace
one of its inputs is refused (exit 2).
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback

from ..errors import InputError
from . import (
    compare,
    css,
    diagnose,
    invert,
    reflection,
    selfcheck,
    shapes,
    simulate,
    sites,
)

__all__ = ["main", "build_parser"]

_REGISTRARS = (selfcheck.register, sites.register, shapes.register, simulate.register,
               css.register, invert.register, diagnose.register, compare.register,
               reflection.register)


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every registered subcommand."""
    parser = argparse.ArgumentParser(
        prog="lightcurve",
        description="Simulate and invert photometric lightcurves of spacecraft; coarse sun "
        "sensor estimation. Run 'lightcurve COMMAND --help' for each command.",
    )
    parser.add_argument("--debug", action="store_true", help="print full tracebacks on errors")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND")
    for reg in _REGISTRARS:
        reg(sub)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``lightcurve`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    from ..io.safe_open import track_inputs
    from ..process import Terminated, exit_code, handle_termination

    try:
        with handle_termination(), track_inputs():
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


def _one_line(exc: BaseException, limit: int = 2000) -> str:
    """The exception's text on one line (newlines folded), at most ``limit`` characters."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
