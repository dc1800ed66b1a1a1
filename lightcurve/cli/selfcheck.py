"""``lightcurve selfcheck`` and ``warmup``: check the installation, compile the kernels once."""

from __future__ import annotations

from ._args import add_command, add_quiet

__all__ = ["register"]


def _cmd_selfcheck(args) -> int:
    """Run quick numerical self-checks of the installed package (rotation algebra against scipy,
    angular-momentum conservation of the rigid-body integrator, offline ephemeris availability)
    and print one line per check.
    """
    from ..selfcheck import run_selfcheck

    ok = run_selfcheck(verbose=not args.quiet)
    return 0 if ok else 1


def _cmd_warmup(args) -> int:
    """Run a tiny simulation and every attitude filter on it so that numba compiles the hot kernels
    and stores them in its on-disk cache (next to the package, or ~/.cache/numba when that is
    read-only). Later processes load them instead of recompiling; also runs a 60 s
    coarse-sun-sensor closed loop per CSS estimator. Safe to run again: then it only loads the
    cache.
    """
    import time

    from ..warmup import warm_up

    t0 = time.perf_counter()
    steps = warm_up(reflection=args.reflection, css=not args.no_css)
    if not args.quiet:
        print("compiled or loaded from the cache: " + ", ".join(
            f"{k} {v:.1f} s" for k, v in steps.items()) + f"; total {time.perf_counter() - t0:.1f} s")
    return 0


def register(sub) -> None:
    p = add_command(
        sub, "selfcheck", _cmd_selfcheck,
        help="check the installation: rotation algebra, dynamics, ephemeris files",
    )
    add_quiet(p, help="print only failures")

    p = add_command(
        sub, "warmup", _cmd_warmup,
        help="compile the numba kernels once (run after installing; later runs start fast)")
    p.add_argument("--reflection", action="store_true",
                   help="also compile the Model 3 reflection-state filters (slower)")
    p.add_argument("--no-css", action="store_true",
                   help="skip the coarse-sun-sensor kernels (compiled by default)")
    add_quiet(p, help="print nothing")
