"""``lightcurve selfcheck``: quick numerical checks of the installation."""

from __future__ import annotations

__all__ = ["register"]


def _cmd_selfcheck(args) -> int:
    from ..selfcheck import run_selfcheck

    ok = run_selfcheck(verbose=not args.quiet)
    return 0 if ok else 1


def register(sub) -> None:
    p = sub.add_parser(
        "selfcheck",
        help="check the installation: rotation algebra, dynamics, ephemeris files",
        description="Run quick numerical self-checks of the installed package (rotation "
        "algebra against scipy, angular-momentum conservation of the rigid-body integrator, "
        "offline ephemeris availability) and print one line per check.",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="print only failures")
    p.set_defaults(func=_cmd_selfcheck)
