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

File modes: the new file gets ``0o666 & ~umask`` (what ``open()`` would give), not the
``0o600`` of a temporary file, so a shared report is readable by whoever the umask allows.

Temporary files are named ``.<name>.<host>-<pid>-<random><suffix>`` (``host`` a 6-hex-digit
hash of the host name, ``suffix`` e.g. ``.png`` or ``.tmp``). A killed writer leaves its temporary file behind; the next write into
the same folder (:func:`clean_stale_temp`) removes those of the same final name whose writer
is provably gone — same host and the pid no longer alive — and, for other hosts (a shared
network folder), those untouched for a day. A live writer's temporary file is never removed.
A worker process that is stopped by SIGTERM in the middle of a write (its handler,
:func:`lightcurve.process.watch_parent`, leaves with ``os._exit`` and so skips the writer's
clean-up) first removes its own temporary files with :func:`remove_own_temp`.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import socket
import tempfile
import time
from pathlib import Path

__all__ = ["atomic_path", "atomic_write_text", "atomic_write_bytes", "fsync_dir",
           "clean_stale_temp", "current_umask", "temp_prefix", "remove_own_temp"]

#: temporary files of other hosts are removed only after this long without a change
FOREIGN_TEMP_AGE_S = 86400.0
_TMP_RE = re.compile(r"^\.(?P<name>.+)\.(?P<host>[0-9a-f]{6})-(?P<pid>[0-9]+)-[a-z0-9_]{8}"
                     r"(?:\.[A-Za-z0-9_.\-]*)?$")


#: (folder, prefix) → number of writes in progress in this process; registered before the
#: temporary file is created, so a signal between its creation and its registration cannot
#: leave it behind
_OWN: dict[tuple[str, str], int] = {}


def remove_own_temp() -> int:
    """Remove the temporary files of this process's writes in progress (for a process about
    to exit without unwinding, e.g. a worker's SIGTERM handler). Returns how many."""
    return sum(_remove_prefixed(folder, prefix) for folder, prefix in list(_OWN))


def _scan(folder) -> list:
    """The entries of ``folder``; none where it cannot be read."""
    try:
        return list(os.scandir(folder))
    except OSError:
        return []


def _remove_prefixed(folder: str, prefix: str) -> int:
    n = 0
    for e in _scan(folder):
        if e.name.startswith(prefix):
            with contextlib.suppress(OSError):
                os.unlink(e.path)
                n += 1
    return n


def _host_tag() -> str:
    return hashlib.sha256(socket.gethostname().encode("utf-8", "replace")).hexdigest()[:6]


def temp_prefix(name: str) -> str:
    """Prefix of this process's temporary files for final name ``name``."""
    return f".{name}.{_host_tag()}-{os.getpid()}-"


def current_umask() -> int:
    """The process umask (read from ``/proc/self/status`` where possible; elsewhere set and
    restored at once)."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    old = os.umask(0o022)
    os.umask(old)
    return old


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def clean_stale_temp(folder, name: str | None = None) -> int:
    """Remove temporary files left in ``folder`` by killed writers (module docstring); only
    those for final name ``name`` when given. Returns how many were removed."""
    folder = Path(folder)
    host = _host_tag()
    now = time.time()
    n = 0
    for e in _scan(folder):
        m = _TMP_RE.match(e.name)
        if m is None or (name is not None and m.group("name") != name):
            continue
        try:
            st = e.stat(follow_symlinks=False)
        except OSError:
            continue
        if m.group("host") == host:
            stale = not _pid_alive(int(m.group("pid")))
        else:
            stale = now - st.st_mtime > FOREIGN_TEMP_AGE_S
        if stale:
            with contextlib.suppress(OSError):
                os.unlink(e.path)
                n += 1
    return n


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

    On an exception the temporary file is removed and ``path`` is left as it was. The file
    gets the umask's mode; stale temporary files of ``path`` left by killed writers are
    removed first (:func:`clean_stale_temp`). While the command line tracks its inputs
    (:func:`lightcurve.io.safe_open.track_inputs`), a ``path`` that is one of them is refused.
    """
    from .safe_open import check_not_input

    path = Path(path)
    check_not_input(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_temp(path.parent, path.name)
    key = (str(path.parent), temp_prefix(path.name))
    _OWN[key] = _OWN.get(key, 0) + 1
    tmp = None
    try:  # from before the temporary file exists: an interruption anywhere removes it
        # the suffix stays last: writers such as matplotlib pick the format from it
        fd, name = tempfile.mkstemp(prefix=key[1], suffix=suffix or ".tmp", dir=path.parent)
        tmp = Path(name)
        try:
            try:
                os.fchmod(fd, 0o666 & ~current_umask())
            except (OSError, AttributeError):  # e.g. Windows: modes do not apply
                pass
        finally:
            os.close(fd)
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        try:
            os.replace(tmp, path)
        except OSError as exc:  # name the file the user asked for, not the temporary one
            raise OSError(exc.errno, exc.strerror, str(path)) from None
    except BaseException:
        if tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
        elif _OWN.get(key) == 1:  # interrupted inside mkstemp: the only write of this name
            _remove_prefixed(*key)
        raise
    finally:
        left = _OWN.get(key, 1) - 1
        if left > 0:
            _OWN[key] = left
        else:
            _OWN.pop(key, None)
    fsync_dir(path.parent)


def atomic_write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically."""
    atomic_write_bytes(path, text.encode(encoding))
