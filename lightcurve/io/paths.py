"""Output paths derived from untrusted names (scenario names, input file stems, site ids).

A name read from a data file (``[scenario].name = "../../etc/x"``) or from an input file's stem
must never place an output outside the folder the user chose. :func:`safe_output_path` turns
such a name into one plain file name inside ``out_dir``.
"""

from __future__ import annotations

import os
import re
import unicodedata
from pathlib import Path

from ..errors import InputError

__all__ = ["safe_output_path", "safe_name", "MAX_NAME_CHARS"]

#: Longest file-name stem produced (most file systems allow 255 bytes per name).
MAX_NAME_CHARS = 120

_ALLOWED = re.compile(r"[^\w.+\-]+")
_RESERVED = {"CON", "PRN", "AUX", "NUL", *(f"COM{i}" for i in range(10)),
             *(f"LPT{i}" for i in range(10))}


def safe_name(name, *, field: str = "name") -> str:
    """A file-name stem made from ``name`` that contains no path separator.

    Unicode is normalised (NFKC) and everything but letters, digits (any script) and
    ``. _ + -`` becomes ``_`` (so ``/``, ``\\``, NUL and control characters never survive);
    leading and trailing dots and underscores are removed (no hidden files, no ``..``); the
    result is at most :data:`MAX_NAME_CHARS` characters and 240 UTF-8 bytes. Windows device
    names get a ``_`` suffix.

    Raises
    ------
    InputError
        ``name`` is not a string or leaves nothing usable (e.g. ``".."``, ``"///"``).
    """
    if not isinstance(name, str):
        raise InputError("expected a text name", field=field, value=name)
    text = unicodedata.normalize("NFKC", name)
    text = _ALLOWED.sub("_", text).strip("._")
    text = text[:MAX_NAME_CHARS]
    while len(text.encode("utf-8")) > 2 * MAX_NAME_CHARS:  # file systems count bytes (255)
        text = text[:-1]
    text = text.rstrip("._")
    if not text or set(text) <= {"_", "."}:
        raise InputError("name gives no usable file name", field=field, value=name,
                         allowed="letters, digits, '.', '_', '+', '-'")
    if text.split(".")[0].upper() in _RESERVED:
        text += "_"
    return text


def safe_output_path(out_dir, name, suffix: str = "", *, field: str = "name") -> Path:
    """``out_dir / (safe_name(name) + suffix)``, guaranteed to lie directly inside ``out_dir``.

    Parameters
    ----------
    out_dir : path-like
        The output folder the user chose (trusted; need not exist yet).
    name : str
        Untrusted stem (scenario name, input file stem...).
    suffix : str
        Extension(s) to append, e.g. ``".h5"`` or ``".ukf.h5"``: only ``.``, letters, digits,
        ``_`` and ``-``.
    field : str
        Where ``name`` came from, for the error message.

    Raises
    ------
    InputError
        Unusable ``name`` (see :func:`safe_name`).
    ValueError
        A bad ``suffix`` (programmer error).
    """
    if not isinstance(suffix, str) or (suffix and not re.fullmatch(r"(\.[A-Za-z0-9_\-]+)+", suffix)):
        raise ValueError(f"safe_output_path: bad suffix {suffix!r}; expected e.g. '.h5'")
    base = Path(out_dir)
    path = base / (safe_name(name, field=field) + suffix)
    # belt and braces: the name is one path component inside the folder (an existing symlink
    # of that name is replaced by the atomic rename, never written through)
    if Path(os.path.normpath(base.resolve() / path.name)).parent != base.resolve():
        raise InputError("output name escapes the output folder", field=field, value=name)
    return path
