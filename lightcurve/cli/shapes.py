"""``lightcurve shapes``: list, show and validate faceted shapes."""

from __future__ import annotations

import argparse

from ..errors import InputError
from ._args import add_command, add_group, add_library

__all__ = ["register"]


def _cmd_shapes_list(args) -> int:
    from ..photometry.shapes_io import load_shape, shape_library

    for name, path in shape_library(_dirs(args)).items():
        try:
            desc = load_shape(path).description
        except InputError as exc:
            desc = f"(invalid: {exc.bare_message})"
        print(f"{name:20s} {desc}")
    return 0


def _cmd_shapes_show(args) -> int:
    from ..photometry.shapes_io import load_shape

    print(load_shape(args.name, library_dirs=_dirs(args)).summary())
    return 0


def _cmd_shapes_validate(args) -> int:
    """Report zero-area or degenerate facets, non-unit normals, materials outside their ranges (xi
    in [0,1], a in (0,1), m in (0,1]) and non-convex shapes (self-shadowing is not modelled).
    Exit code 0: no problems (or only non-convexity); 2: problems.
    """
    from ..photometry.shapes_io import validate_shape

    problems = validate_shape(args.spec, library_dirs=_dirs(args))
    for p in problems:
        print(p)
    if not problems:
        print(f"{args.spec}: OK")
    # non-convexity alone is a warning (exit 0); anything else is a problem (exit 2)
    from ..photometry.shapes_io import NONCONVEX_NOTE

    return 2 if any(NONCONVEX_NOTE not in p for p in problems) else 0


def _sub_library(q) -> None:
    """``--library`` after the action too (``shapes list --library DIR``); merged with the
    folders given before it by :func:`_dirs`."""
    q.add_argument("--library", action="append", metavar="DIR", default=argparse.SUPPRESS,
                   dest="library_sub",
                   help="extra shape library folder, searched before the bundled shapes/ "
                   "(repeatable; also accepted before the action)")


def _dirs(args):
    return (args.library or []) + list(getattr(args, "library_sub", []) or []) or None


def register(sub) -> None:
    p, ssub = add_group(
        sub, "shapes", title="shape commands", metavar="ACTION",
        help="list, show and validate faceted shapes",
        description="Faceted shape library: bundled shapes/ plus folders given with --library. "
        "Shapes are TOML facet lists or OBJ/STL meshes with a TOML material map.")
    add_library(p)
    pl = add_command(ssub, "list", _cmd_shapes_list, help="list the shapes in the library")
    _sub_library(pl)
    ps = add_command(ssub, "show", _cmd_shapes_show,
                     help="print a shape's facets, materials and mass properties")
    ps.add_argument("name", help="library name or path to a shape TOML")
    _sub_library(ps)
    pv = add_command(
        ssub, "validate", _cmd_shapes_validate,
        help="check a shape: degenerate facets, normals, material ranges, convexity")
    pv.add_argument("spec", metavar="PATH_OR_NAME", help="library name or path to a shape TOML")
    _sub_library(pv)
