"""Memory estimates before allocation: refuse a run that cannot fit, before it starts.

A small input can ask for unbounded memory (a scenario of 5·10⁷ epochs, ``--particles 10⁷``,
``--walkers 10⁵``, ``css simulate`` at 1 ms for a year, an HDF5 file declaring 10⁸ rows).
Code that allocates in proportion to a user-given number estimates the bytes first and calls
:func:`check_allocation`, which raises :class:`~lightcurve.errors.InputError` (command-line
exit 2) naming what needs the memory, the estimate and the limit — before anything is
allocated.

The limit (:func:`memory_limit`) is the environment variable ``LIGHTCURVE_MEMORY_LIMIT``
(bytes, or with a unit: ``512M``, ``8GiB``, ``1.5G``; ``0`` or ``none`` disables the check),
else half the physical memory, lowered to the cgroup (container) limit when one is set.
Estimates count the dominant arrays only (they are lower bounds of the real peak, which also
holds the interpreter, libraries and temporaries).
"""

from __future__ import annotations

import os
import re

from .errors import InputError

__all__ = ["memory_limit", "check_allocation", "format_bytes", "parse_bytes", "ENV_VAR"]

ENV_VAR = "LIGHTCURVE_MEMORY_LIMIT"
_UNITS = {"": 1, "b": 1, "k": 1000, "kb": 1000, "kib": 1024, "m": 1000**2, "mb": 1000**2,
          "mib": 1024**2, "g": 1000**3, "gb": 1000**3, "gib": 1024**3, "t": 1000**4,
          "tb": 1000**4, "tib": 1024**4}


def parse_bytes(text: str) -> int | None:
    """``"8GiB"`` → 8589934592; ``"0"``/``"none"``/``"off"`` → None (no limit).

    Raises InputError naming the environment variable for anything else.
    """
    t = str(text).strip().lower().replace(" ", "")
    if t in ("0", "none", "off", "unlimited"):
        return None
    m = re.fullmatch(r"([0-9]+(?:\.[0-9]*)?(?:e[0-9]+)?)([a-z]*)", t)
    if not m or m.group(2) not in _UNITS:
        raise InputError("cannot read the memory limit", field=ENV_VAR, value=text,
                         allowed="bytes, or a number with K, M, G, T (powers of 1000) or KiB, "
                         "MiB, GiB, TiB; 0 or none for no limit")
    v = float(m.group(1)) * _UNITS[m.group(2)]
    if not (v >= 1):
        raise InputError("memory limit must be at least 1 byte", field=ENV_VAR, value=text)
    return int(v)


def format_bytes(n) -> str:
    """``3.2 GiB`` style text of a byte count."""
    n = float(n)
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} bytes" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} EiB"  # pragma: no cover


def _physical_bytes() -> int | None:
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def _cgroup_bytes() -> int | None:
    for f in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(f, encoding="ascii") as fh:
                t = fh.read().strip()
        except OSError:
            continue
        if t.isdigit() and int(t) < 2**60:
            return int(t)
    return None


def memory_limit() -> tuple[int | None, str]:
    """``(limit in bytes or None for no limit, where it comes from)`` (module docstring)."""
    env = os.environ.get(ENV_VAR)
    if env is not None and env.strip():
        v = parse_bytes(env)
        return v, f"{ENV_VAR}={env.strip()}"
    phys = _physical_bytes()
    cg = _cgroup_bytes()
    cands = [(x // 2, why) for x, why in ((phys, "half the physical memory"),
                                          (cg, "half the cgroup memory limit")) if x]
    if not cands:
        return None, "no limit known"
    v, why = min(cands)
    return v, f"{why}; set {ENV_VAR} to change"


def check_allocation(nbytes, what: str, *, file=None, field=None, value=None) -> int:
    """Refuse (InputError) when ``nbytes`` exceed :func:`memory_limit`; return ``nbytes``.

    Parameters
    ----------
    nbytes : int or float — estimated bytes of the dominant arrays (may be huge or inf)
    what : str — what needs them, e.g. ``"particle filter: 10000000 particles x 5000 epochs"``
    file, field, value : for the message (the option or key that set the size)
    """
    limit, why = memory_limit()
    n = float(nbytes)
    if limit is not None and not (n <= limit):
        raise InputError(f"{what} would need about {format_bytes(n)} of memory", file=file,
                         field=field, value=value, allowed=f"<= {format_bytes(limit)} ({why})")
    return int(n) if n < 2**63 else 2**63 - 1
