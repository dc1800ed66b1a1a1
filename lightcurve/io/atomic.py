"""Atomic, durable file writes: write to a temporary file in the same folder, flush it to
disk, rename it onto the final name, then flush the folder.

A crash or an exception in the middle of a write never leaves a half-written file under the
final name, and never destroys a previous version of it. Durability: the temporary file is
``fsync``-ed before the rename (so the name never points at data still in the page cache), and
the folder is ``fsync``-ed after it (so the rename itself survives a power loss) where the OS
allows it — POSIX folders can be opened read-only and synced; on Windows (no ``O_DIRECTORY``,
folders cannot be opened) and on file systems that refuse ``fsync`` on a folder (``EINVAL``,
``ENOTSUP``, ``EBADF``, ``EACCES``) that last step is skipped: the rename is still atomic, only
its durability across a crash is up to the OS.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_path", "atomic_write_text", "atomic_write_bytes", "fsync_dir"]


def fsync_dir(folder) -> bool:
    """Flush a folder's entries (a rename into it) to disk; True if done, False where the OS
    or the file system does not allow it (module docstring)."""
    flags = getattr(os, "O_DIRECTORY", None)
    if flags is None:                     # Windows: folders cannot be opened and synced
        return False
    try:
        fd = os.open(folder, os.O_RDONLY | flags)
    except OSError:
        return False
    try:
        os.fsync(fd)
        return True
    except OSError:                       # EINVAL/ENOTSUP/EBADF on some file systems
        return False
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path beside ``path``; on success fsync it, rename it onto ``path`` and
    fsync the folder (:func:`fsync_dir`).

    On an exception the temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or ".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    fsync_dir(path.parent)


def atomic_write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically."""
    atomic_write_bytes(path, text.encode(encoding))
