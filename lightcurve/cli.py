"""The ``lightcurve`` command line.

Each area registers its subcommands in one ``_register_<area>`` function below; handlers are
thin: they parse arguments, call the library and print. Exit codes: 0 success, 1 run-time
failure, 2 bad usage or bad input (one clear line; the traceback only with ``--debug``).
"""

from __future__ import annotations

import argparse
import sys

from .errors import InputError

__all__ = ["main", "build_parser"]


# ----------------------------------------------------------------------------------------
# self-check (foundation)
# ----------------------------------------------------------------------------------------
def _cmd_selfcheck(args) -> int:
    from .selfcheck import run_selfcheck

    ok = run_selfcheck(verbose=not args.quiet)
    return 0 if ok else 1


def _register_core(sub) -> None:
    p = sub.add_parser(
        "selfcheck",
        help="check the installation: rotation algebra, dynamics, ephemeris files",
        description="Run quick numerical self-checks of the installed package (rotation "
        "algebra against scipy, angular-momentum conservation of the rigid-body integrator, "
        "offline ephemeris availability) and print one line per check.",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="print only failures")
    p.set_defaults(func=_cmd_selfcheck)


# ----------------------------------------------------------------------------------------
# geometry (sites)
# ----------------------------------------------------------------------------------------
def _register_geometry(sub) -> None:
    pass


# ----------------------------------------------------------------------------------------
# photometry (shapes)
# ----------------------------------------------------------------------------------------
def _register_photometry(sub) -> None:
    pass


# ----------------------------------------------------------------------------------------
# simulation, plotting
# ----------------------------------------------------------------------------------------
def _register_simulation(sub) -> None:
    pass


# ----------------------------------------------------------------------------------------
# coarse sun sensors
# ----------------------------------------------------------------------------------------
def _register_css(sub) -> None:
    pass


_REGISTRARS = (_register_core, _register_geometry, _register_photometry, _register_simulation,
               _register_css)


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
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        if args.debug:
            raise
        print(f"lightcurve: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("lightcurve: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # run-time failure: one line unless --debug
        if args.debug:
            raise
        print(f"lightcurve: failed: {type(exc).__name__}: {exc} (run with --debug for details)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
