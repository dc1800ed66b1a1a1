"""One writer per output folder: an advisory lock on ``DIR/.lightcurve.lock``.

``lightcurve compare`` and the batch ``lightcurve invert`` hold the lock of their output
folder while they work, so two runs on one folder do not both do (and overwrite) all the
work: the second is refused at once with one line naming the process that holds the folder
(exit 2). The lock is ``flock(LOCK_EX | LOCK_NB)`` on an open descriptor: the kernel drops
it when the holder exits or is killed (no stale lock to remove by hand). On systems without
``fcntl`` (Windows) no lock is taken.
"""

from __future__ import annotations

import contextlib
import os
import socket
import stat
from pathlib import Path

from ..errors import InputError

__all__ = ["folder_lock", "LOCK_NAME"]

LOCK_NAME = ".lightcurve.lock"


def _holder(path: Path) -> str:
    from .safe_open import read_bytes

    try:
        text = read_bytes(path, max_bytes=4096, what="lock file", track=False)
    except InputError:
        return "another process"
    text = text.decode("utf-8", "replace").strip()[:200]
    return f"process {text}" if text else "another process"


@contextlib.contextmanager
def folder_lock(folder, *, what: str = "output folder"):
    """Hold the lock of ``folder`` (created if missing) for the duration of the block.

    Raises
    ------
    InputError
        Another process holds it (the message names its pid and host).
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0)
                     | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0), 0o666)
    except OSError as exc:
        raise InputError(f"cannot open the lock file: {exc.strerror}", file=path) from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise InputError("the lock file is not a regular file", file=path,
                             allowed="a regular file (remove it)")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"the {what} is in use by {_holder(path)}", file=folder,
                             allowed="one lightcurve run per output folder at a time; wait "
                             "for it to finish, or choose another output folder") from None
        # who holds it, for the message of a second run (informational only)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()} on {socket.gethostname()}\n".encode(), 0)
        try:
            yield
        finally:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)
