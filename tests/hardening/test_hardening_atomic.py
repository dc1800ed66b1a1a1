"""Every file the package writes goes through lightcurve.io.atomic (docs/robustness.md).

1. A source audit: each write call in lightcurve/ (open(..., "w"), savefig, h5py.File(..., "w"),
   np.save/savetxt, json.dump, Path.write_text/write_bytes) sits inside an ``atomic_path``
   block (or writes to an in-memory buffer), so a new non-atomic write fails this test.
2. Behaviour: a write interrupted by an exception leaves the previous file intact and no
   temporary file behind; a truncated result is detected on reading.
"""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from hardening_util import small_curve
from lightcurve import InputError
from lightcurve.io.lightcurve_h5 import read_lightcurve

PKG = Path(__file__).resolve().parents[2] / "lightcurve"

WRITE = re.compile(r"open\([^)]*['\"](w|a|x|wb|ab|r\+b?)['\"]|\.savefig\(|h5py\.File\([^)]*['\"](w|a|x|r\+)['\"]"
                   r"|np\.save(txt|z|z_compressed)?\(|json\.dump\(|\.write_text\(|\.write_bytes\(|\.to_csv\(")
#: (file, text on the line) of writes that are not files: stdout redirection, in-memory buffers
# in-memory targets (BytesIO buffers for base64-embedded figures) are not files
ALLOWED = [("cli/__init__.py", "os.devnull"), ("report/html.py", "savefig(buf")]


def _writes():
    for f in sorted(PKG.rglob("*.py")):
        rel = f.relative_to(PKG).as_posix()
        if rel == "io/atomic.py":
            continue
        lines = f.read_text(encoding="utf-8").splitlines()
        for i, line in enumerate(lines):
            code = line.split("#", 1)[0]
            if WRITE.search(code):
                yield rel, i, lines


def test_every_write_is_atomic():
    offenders = []
    n = 0
    for rel, i, lines in _writes():
        n += 1
        line = lines[i]
        if any(rel == a and frag in line for a, frag in ALLOWED):
            continue
        # inside `with atomic_path(...) as tmp:` : an enclosing line with smaller indentation
        indent = len(line) - len(line.lstrip())
        ok = False
        for j in range(i - 1, max(i - 15, -1), -1):
            prev = lines[j]
            if not prev.strip():
                continue
            pind = len(prev) - len(prev.lstrip())
            if pind < indent and "atomic_path(" in prev:
                ok = True
                break
            if pind < indent and prev.lstrip().startswith(("def ", "class ")):
                break
        # the target is the temporary path yielded by atomic_path
        ok = ok and re.search(r"\btmp\b", line) is not None
        if not ok:
            offenders.append(f"{rel}:{i + 1}: {line.strip()}")
    assert n >= 5, "the audit found suspiciously few writes; is the pattern still right?"
    assert not offenders, "non-atomic writes:\n" + "\n".join(offenders)


def test_interrupted_write_keeps_previous_file(tmp_path, monkeypatch):
    path = tmp_path / "lc.h5"
    lc = small_curve()
    lc.write(path)
    before = path.read_bytes()

    class Boom(RuntimeError):
        pass

    real = h5py.File

    def failing(name, mode="r", *a, **k):
        f = real(name, mode, *a, **k)
        if mode == "w":
            f.attrs["partial"] = 1
            f.close()
            raise Boom("disk full")
        return f

    monkeypatch.setattr(h5py, "File", failing)
    with pytest.raises(Boom):
        lc.write(path)
    monkeypatch.setattr(h5py, "File", real)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lc.h5"]  # no temporary left behind
    back = read_lightcurve(path)
    np.testing.assert_array_equal(back.mag, lc.mag)


@pytest.mark.parametrize("keep", [0.1, 0.5, 0.9, 0.99])
def test_truncated_hdf5_detected(tmp_path, keep):
    """A file cut short (e.g. a copy interrupted outside our atomic writes) is an InputError."""
    path = tmp_path / "lc.h5"
    small_curve(200).write(path)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(InputError, match="lc.h5"):
        read_lightcurve(path)


UNSAFE = re.compile(r"\beval\(|\bexec\(|\bpickle\b|\bmarshal\b|\bdill\b|\bjoblib\b|\brunpy\b|__import__\("
                    r"|yaml\.load\(|allow_pickle\s*=\s*True|np\.load\(|numpy\.load\(|import_module\(")
#: lines that match UNSAFE but are not driven by data: (file, text on the line, why)
SAFE_LOADS = [
    ("css/study.py", "np.load(fh, allow_pickle=False)", "the study's own .npz run files, "
     "NumPy arrays only, opened through io.safe_open"),
    ("plugins.py", "importlib.import_module(key)", "--plugin MODULE: a module the user names on "
     "the command line, never a name read from a data file"),
]


def test_no_code_or_pickle_loading_from_data():
    """No eval/exec, no pickle (np.load only with allow_pickle=False, on the program's own
    files), no imports driven by data. The only dynamic loading is BRDF plug-ins registered by
    installed packages through entry points (photometry/brdf.py: only the one named) and
    ``--plugin`` modules named on the command line (SAFE_LOADS), never a name read from a
    data file."""
    hits = []
    for f in sorted(PKG.rglob("*.py")):
        rel = f.relative_to(PKG).as_posix()
        for i, line in enumerate(f.read_text(encoding="utf-8").splitlines()):
            code = line.split("#", 1)[0]
            if UNSAFE.search(code) and not any(rel == a and frag in code
                                               for a, frag, _ in SAFE_LOADS):
                hits.append(f"{rel}:{i + 1}: {line.strip()}")
    assert not hits, "unsafe loading:\n" + "\n".join(hits)


def test_atomic_write_fsyncs_file_then_folder(tmp_path, monkeypatch):
    """Durability (every write is atomic): the data is fsync-ed before the rename,
    the folder after it (POSIX); the rename semantics are unchanged — the final name holds the
    new bytes, a previous version is replaced whole, no temporary file is left."""
    import os
    import stat

    from lightcurve.io import atomic

    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        mode = os.fstat(fd).st_mode
        events.append(("fsync", "dir" if stat.S_ISDIR(mode) else "file"))
        return real_fsync(fd)

    def replace(a, b):
        events.append(("rename", Path(b).name))
        return real_replace(a, b)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    path = tmp_path / "out" / "a.txt"
    atomic.atomic_write_text(path, "first\n")
    atomic.atomic_write_text(path, "second\n")
    assert path.read_text() == "second\n"
    assert sorted(p.name for p in path.parent.iterdir()) == ["a.txt"]
    one = [("fsync", "file"), ("rename", "a.txt")]
    if hasattr(os, "O_DIRECTORY"):
        one.append(("fsync", "dir"))
    assert events == one + one


def test_atomic_write_exception_cleans_up_and_skips_fsync(tmp_path, monkeypatch):
    """An exception inside the block: no rename, no fsync of the folder, the temporary file is
    removed and the previous file is untouched. A folder that cannot be synced (EINVAL on
    some file systems) does not fail the write."""
    import errno
    import os

    from lightcurve.io import atomic

    path = tmp_path / "b.bin"
    atomic.atomic_write_bytes(path, b"old")
    calls = []
    monkeypatch.setattr(os, "fsync", lambda fd: calls.append(fd))
    with pytest.raises(KeyboardInterrupt):
        with atomic.atomic_path(path) as tmp:
            tmp.write_bytes(b"half")
            raise KeyboardInterrupt
    assert path.read_bytes() == b"old" and calls == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.bin"]

    def refuse(fd):
        raise OSError(errno.EINVAL, "fsync not supported on this folder")

    real_fsync = os.fsync

    def fsync(fd):
        import stat

        if stat.S_ISDIR(os.fstat(fd).st_mode):
            refuse(fd)
        return real_fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    atomic.atomic_write_bytes(path, b"new")
    assert path.read_bytes() == b"new"
    assert atomic.fsync_dir(tmp_path) is False or not hasattr(os, "O_DIRECTORY")


@pytest.mark.parametrize("where", ["mkstemp", "umask", "fsync"])
def test_interruption_between_creating_and_using_the_temporary_file(where, tmp_path, monkeypatch):
    """Ctrl-C (or SIGTERM, which raises like it in the command line) may land at any bytecode:
    also after the temporary file was created but before the block's body runs (setting its
    mode), or inside mkstemp after the file exists. No temporary file may stay, the previous
    file is untouched, and a later write of the same name works."""
    import os
    import tempfile

    from lightcurve.io import atomic

    path = tmp_path / "c.bin"
    atomic.atomic_write_bytes(path, b"old")

    def interrupt(*a, **k):
        raise KeyboardInterrupt

    if where == "mkstemp":
        real = tempfile.mkstemp

        def mkstemp(*a, **k):
            fd, name = real(*a, **k)  # the file exists, the caller never sees its name
            os.close(fd)
            raise KeyboardInterrupt
        monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    elif where == "umask":
        monkeypatch.setattr(atomic, "current_umask", interrupt)
    else:
        monkeypatch.setattr(os, "fsync", interrupt)
    with pytest.raises(KeyboardInterrupt):
        atomic.atomic_write_bytes(path, b"new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.bin"]
    assert path.read_bytes() == b"old" and atomic._OWN == {}
    monkeypatch.undo()
    atomic.atomic_write_bytes(path, b"new")
    assert path.read_bytes() == b"new"


@pytest.mark.skipif(not hasattr(__import__("signal"), "SIGTERM") or __import__("sys").platform
                    == "win32", reason="POSIX signals")
def test_worker_stopped_by_sigterm_mid_write_leaves_no_temporary_file(tmp_path):
    """A pool worker's SIGTERM handler (lightcurve.process.watch_parent) leaves with os._exit,
    which skips atomic_path's own clean-up; it must remove the temporary file of the write in
    progress itself. Checked with a child process stopped inside the write, and a control child
    killed by SIGKILL (no handler runs) that does leave its file: the check can fail."""
    import os
    import signal
    import subprocess
    import sys

    code = ("import os, sys, signal, time\n"
            "from lightcurve.process import _exit_now\n"
            "from lightcurve.io.atomic import atomic_path\n"
            "signal.signal(signal.SIGTERM, _exit_now)\n"
            "with atomic_path(sys.argv[1], suffix='.h5.tmp') as tmp:\n"
            "    tmp.write_bytes(b'x' * 1000)\n"
            "    print('writing', flush=True)\n"
            "    time.sleep(60)\n")
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    left = {}
    for sig in (signal.SIGTERM, signal.SIGKILL):
        folder = tmp_path / sig.name
        folder.mkdir()
        proc = subprocess.Popen([sys.executable, "-c", code, str(folder / "run.h5")], env=env,
                                stdout=subprocess.PIPE)
        try:
            assert proc.stdout.readline().strip() == b"writing"
            assert len(list(folder.glob(".*"))) == 1  # the write is in progress
            proc.send_signal(sig)
            rc = proc.wait(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            proc.stdout.close()
        assert rc == (128 + signal.SIGTERM if sig == signal.SIGTERM else -signal.SIGKILL)
        assert not (folder / "run.h5").exists()
        left[sig.name] = sorted(p.name for p in folder.iterdir())
    assert left["SIGTERM"] == []
    assert len(left["SIGKILL"]) == 1 and left["SIGKILL"][0].startswith(".run.h5.")
