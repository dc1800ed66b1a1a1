"""Signals: SIGTERM and SIGHUP end a command like Ctrl-C (exit 143 / 129, one line saying how
to resume, stored runs kept), and no process of a `compare` pool — workers, forkserver,
resource tracker — survives the main process, whether it was terminated or SIGKILLed: after
5 s none is alive and the caller's pipe reaches end-of-file (`lightcurve compare … | cat`
ends). Before, the workers were re-parented to init and kept the pipe open for ever.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lightcurve.cli import main

ROOT = Path(__file__).resolve().parents[2]

SCENARIO = """
[scenario]
name = "tiny"
epoch_utc = "2020-03-01T08:08:40Z"
duration_s = 60.0
cadence_s = 5.0
seed = 1
[orbit]
type = "keplerian"
a_km = 6871.14
e = 0.01
i_deg = 83.0
raan_deg = 0.0
argp_deg = 0.0
nu_deg = 126.264
gravity = "J4"
[shape]
name = "cube_1u"
[attitude]
dynamics = "controlled"
euler321_deg = [-42.4122, 59.1601, 48.9897]
omega_deg_s = [2.0, 1.0, 3.6]
acs_sigma_deg = 0.1
[[sites]]
name = "socorro"
windows_s = [[0.0, 60.0]]
[measurement]
r_percent = 1.0
ignore_eclipse = true
"""

STUDY = """
[study]
name = "signals"
seed = 3
runs = 2000
scenario = "tiny-{dynamics}-{sites}site.toml"
[grid]
filter = ["ukf", "mekf"]
dynamics = ["controlled"]
sites = [1]
sigma_theta_deg = [3.0]
sigma_omega_deg_s = [0.02]
r_percent = [1.0]
"""


def _stat(pid):
    """(ppid, state, start time) of a process, or None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    rest = text[text.rindex(")") + 2:].split()
    return int(rest[1]), rest[0], rest[19]


def _descendants(root):
    """{pid: start time} of every process below ``root`` (from /proc)."""
    kids = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            st = _stat(int(d))
            if st is not None:
                kids.setdefault(st[0], []).append((int(d), st[2]))
    out, todo = {}, [root]
    while todo:
        for pid, start in kids.get(todo.pop(), []):
            out[pid] = start
            todo.append(pid)
    return out


def _alive(procs):
    """The processes of ``procs`` ({pid: start}) still running (zombies count as gone)."""
    out = []
    for pid, start in procs.items():
        st = _stat(pid)
        if st is not None and st[2] == start and st[1] != "Z":
            out.append(pid)
    return out


def _read_to_eof(fd, timeout_s):
    """Everything written to the pipe until every writer closed it; None after timeout_s."""
    data, end = b"", time.monotonic() + timeout_s
    while True:
        left = end - time.monotonic()
        if left <= 0:
            return None
        r, _, _ = select.select([fd], [], [], left)
        if r:
            chunk = os.read(fd, 65536)
            if not chunk:
                return data
            data += chunk


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig, executor", [
    (signal.SIGTERM, ("--workers", "2")), (signal.SIGKILL, ("--workers", "2")),
    (signal.SIGKILL, ("--dask-local", "2")),  # the LocalCluster's worker processes
], ids=["SIGTERM-pool", "SIGKILL-pool", "SIGKILL-dask-local"])
def test_killed_compare_leaves_no_process_and_closes_the_pipe(sig, executor, tmp_path):
    if "--dask-local" in executor:
        pytest.importorskip("distributed", reason="the 'distributed' extra is not installed")
    (tmp_path / "tiny-controlled-1site.toml").write_text(SCENARIO)
    (tmp_path / "study.toml").write_text(STUDY)
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    # like `lightcurve compare … 2>&1 | cat`: one pipe for stdout and stderr
    proc = subprocess.Popen([sys.executable, "-m", "lightcurve", "compare", "study.toml", "-o",
                             str(out), *executor, "-q"], env=env, cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    procs = {}
    need = 3 if "--dask-local" in executor else 4
    try:
        deadline = time.monotonic() + 180
        runs = out / "runs"
        while time.monotonic() < deadline and proc.poll() is None:
            procs.update(_descendants(proc.pid))
            stored = len(list(runs.glob("*.h5"))) if runs.is_dir() else 0
            # pool running: forkserver + resource tracker + 2 workers (Dask: the nannies live in
            # the main process; 2 worker processes + resource tracker), and runs stored
            if len(procs) >= need and stored >= 2:
                break
            time.sleep(0.05)
        assert proc.poll() is None, f"compare ended early: {proc.communicate()}"
        procs.update(_descendants(proc.pid))
        assert len(procs) >= need, procs
        os.kill(proc.pid, sig)  # the main process only, as `kill PID` does
        text = _read_to_eof(proc.stdout.fileno(), 30 if sig == signal.SIGTERM else 10)
        code = proc.wait(timeout=30)
        t_end = time.monotonic() + 5
        while _alive(procs) and time.monotonic() < t_end:
            time.sleep(0.1)
        left = _alive(procs)
        assert not left, f"processes alive 5 s after the main process ended: {left}"
        assert text is not None, "a child process still holds the caller's pipe"
    finally:
        for pid in _alive(procs):  # never leave this test's processes behind
            os.kill(pid, signal.SIGKILL)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
    stored = {p.name for p in runs.glob("*.h5") if not p.name.startswith(".")}
    assert len(stored) >= 2  # finished runs kept
    if sig == signal.SIGTERM:
        assert code == 143
        lines = [ln for ln in text.decode().splitlines() if ln.strip()]
        assert lines[-1].startswith("lightcurve: terminated by SIGTERM"), lines
        assert "run the same command again to resume" in lines[-1]
        assert not list(runs.glob(".*"))  # no temporary file left
    else:
        assert code == -signal.SIGKILL


@pytest.mark.parametrize("signame, code", [("SIGTERM", 143), ("SIGHUP", 129)])
def test_sigterm_and_sighup_end_like_ctrl_c(signame, code, capsys, monkeypatch):
    """In-process: a command that receives the signal unwinds (its finally blocks run) and
    main() returns 128 + signal with one line; the handlers are restored afterwards."""
    import lightcurve.cli as cli

    sig = getattr(signal, signame)

    class NotHandled(Exception):
        pass

    def fallback(signum, frame):  # replaced by main()'s handler while the command runs
        raise NotHandled(signame)

    prev = signal.signal(sig, fallback)
    before = signal.getsignal(sig)
    unwound = []

    def cmd(args):
        try:
            os.kill(os.getpid(), sig)
            time.sleep(10)  # interrupted by the handler's exception
        finally:
            unwound.append(True)
        return 0

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    parser._subparsers._group_actions[0].choices["selfcheck"].set_defaults(func=cmd)
    try:
        t0 = time.monotonic()
        assert main(["selfcheck"]) == code
        assert time.monotonic() - t0 < 9 and unwound == [True]
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"lightcurve: terminated by {signame}"]
        assert signal.getsignal(sig) == before
    finally:
        signal.signal(sig, prev)


@pytest.mark.parametrize("signame", ["SIGTERM", "SIGINT"])
def test_signal_swallowed_in_a_weakref_callback_is_delivered_again(signame):
    """A signal whose handler runs inside a weakref callback (where Python only prints
    "Exception ignored in" and goes on) still ends the block: it is delivered again from
    ordinary code. Before, the SIGTERM was lost and later ones ignored — a `compare
    --dask-local` killed with SIGTERM ran all its remaining runs and exited 0."""
    import gc
    import weakref

    from lightcurve.process import Terminated, handle_termination

    sig = getattr(signal, signame)
    expected = Terminated if signame == "SIGTERM" else KeyboardInterrupt
    prev_int = signal.signal(signal.SIGINT, signal.default_int_handler)

    class Obj:
        pass

    def callback(ref):  # the handler runs here, between two of these bytecodes
        os.kill(os.getpid(), sig)
        for _ in range(10000):
            pass

    swallowed = []
    old_hook = sys.unraisablehook
    try:
        with pytest.raises(expected):
            with handle_termination():
                hook = sys.unraisablehook

                def spy(u):  # the exception really is lost in the callback first
                    swallowed.append(type(u.exc_value))
                    hook(u)

                sys.unraisablehook = spy
                obj = Obj()
                ref = weakref.ref(obj, callback)
                del obj
                gc.collect()
                t0 = time.monotonic()
                while time.monotonic() - t0 < 5:  # ordinary code: the re-delivery lands here
                    time.sleep(0.01)
        assert swallowed and issubclass(swallowed[0], KeyboardInterrupt), swallowed
        assert ref() is None
    finally:
        sys.unraisablehook = old_hook
        signal.signal(signal.SIGINT, prev_int)


def test_stop_pool_terminates_busy_workers():
    """lightcurve.process.stop_pool ends workers busy with long tasks at once instead of
    waiting for the tasks (what `with ProcessPoolExecutor` does on an exception)."""
    from lightcurve.process import stop_pool
    from lightcurve.studies.runner import process_pool

    ex = process_pool(2)
    futs = [ex.submit(time.sleep, 60) for _ in range(4)]
    t_end = time.monotonic() + 60
    while len(getattr(ex, "_processes", {}) or {}) < 2 and time.monotonic() < t_end:
        time.sleep(0.05)
    procs = list(ex._processes.values())
    assert procs, "no worker started within 60 s"
    manager = ex._executor_manager_thread
    stop_pool(ex, grace_s=2.0)
    assert all(not p.is_alive() for p in procs)
    assert all(f.cancelled() or f.done() for f in futs)
    # the executor's manager thread is gone before stop_pool returns: it no longer races
    # stop_pool to fail the same futures (an InvalidStateError traceback on stderr)
    assert manager is None or not manager.is_alive()


def test_worker_dies_with_its_parent(tmp_path):
    """watch_parent: a process whose watched parent is SIGKILLed dies within seconds."""
    code = (
        "import os, sys, time\n"
        "pid = os.fork()\n"
        "if pid == 0:\n"
        "    from lightcurve.process import watch_parent\n"
        "    watch_parent(int(sys.argv[1]))\n"
        "    sys.stdout.write(f'{os.getpid()}\\n'); sys.stdout.flush()\n"
        "    time.sleep(120)\n"
        "    os._exit(0)\n"
        "time.sleep(120)\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    # the middle process is the watched parent; its child is the "worker"
    middle = subprocess.Popen([sys.executable, "-c", code.replace("int(sys.argv[1])",
                               "os.getppid()")], env=env, stdout=subprocess.PIPE)
    try:
        line = _read_line(middle.stdout.fileno(), 60)
        child = int(line)
        start = _stat(child)[2]
        os.kill(middle.pid, signal.SIGKILL)
        middle.wait(10)
        t_end = time.monotonic() + 5
        while _alive({child: start}) and time.monotonic() < t_end:
            time.sleep(0.05)
        assert not _alive({child: start})
    finally:
        if middle.poll() is None:
            middle.kill()
            middle.wait()
        middle.stdout.close()


def _read_line(fd, timeout_s):
    data, end = b"", time.monotonic() + timeout_s
    while b"\n" not in data:
        r, _, _ = select.select([fd], [], [], max(0.0, end - time.monotonic()))
        if not r:
            raise TimeoutError("no line")
        chunk = os.read(fd, 100)
        if not chunk:
            raise EOFError
        data += chunk
    return data.split(b"\n")[0]
