"""Bounded reads of untrusted text files (recordings, element sets).

:func:`read_text_capped` opens without blocking (a FIFO or a terminal never hangs the
reader), checks on the open descriptor that the file is a regular file (``/dev/zero``, FIFOs,
sockets and folders are refused), refuses a file larger than the cap before reading it and
reads at most ``max_bytes + 1`` bytes (a file growing while read is refused too). Every
failure is an :class:`~lightcurve.errors.InputError` naming the file, the size and the limit.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import InputError

__all__ = ["read_text_capped"]


def read_text_capped(path, *, max_bytes: int, what: str = "file") -> str:
    """UTF-8 text (a leading BOM removed) of a regular file of at most ``max_bytes`` bytes."""
    path = Path(path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise InputError("file not found", file=path) from None
    except OSError as exc:
        raise InputError(f"cannot open the {what}: {exc.strerror or exc}", file=path) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"not a regular file (the {what} must be a plain file)", file=path)
        if st.st_size > max_bytes:
            raise InputError(f"{what} too large", file=path, value=f"{st.st_size} bytes",
                             allowed=f"<= {max_bytes} bytes")
        with os.fdopen(fd, "rb", closefd=True) as fh:
            fd = None
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise InputError(f"cannot read the {what}: {exc.strerror or exc}", file=path) from None
    finally:
        if fd is not None:
            os.close(fd)
    if len(data) > max_bytes:
        raise InputError(f"{what} too large (grew while read)", file=path,
                         allowed=f"<= {max_bytes} bytes")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"not a UTF-8 text file: byte {exc.start} cannot be decoded",
                         file=path) from None
