"""Shared argument types and option spellings of the ``lightcurve`` command line.

Every subcommand builds its options from these helpers so that one option is spelled one way
everywhere (``-o/--output``, ``--library``, ``--sites``, ``--seed``, ``--workers``); a bad number
is a usage error (exit 2) at parse time, never a crash later on.
"""

from __future__ import annotations

import argparse

import numpy as np

from ..errors import InputError

__all__ = ["number", "SEED", "csv_list", "csv_ints", "output_not_input"]


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
