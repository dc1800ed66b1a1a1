"""Process life cycle: termination signals in the command line, and worker processes that never
outlive the run that started them.

* :func:`handle_termination` (used by :func:`lightcurve.cli.main`): SIGTERM and SIGHUP raise
  :class:`Terminated` (a :class:`KeyboardInterrupt`), so they unwind exactly like Ctrl-C —
  stored runs are kept, temporary files removed, process pools stopped — and the command line
  exits with 128 + the signal number (143 for SIGTERM, 129 for SIGHUP; 130 for SIGINT).
* :func:`watch_parent` (run in every worker process by the pool initialiser): the worker exits
  when the process that started the run dies, even by SIGKILL. On Linux the kernel signals it
  (``prctl(PR_SET_PDEATHSIG, SIGTERM)``: fires when the worker's parent — the forkserver, which
  itself exits when the main process is gone — dies); everywhere, a daemon thread waits on a
  ``pidfd`` of the main process (Linux ≥ 5.3) or polls it once a second, and sends the worker
  SIGTERM when it is gone, then SIGKILL 3 s later if it is still there. A worker's SIGTERM
  handler exits at once after running the process's exit finalisers (so the semaphores numba
  registers with multiprocessing's resource tracker are released, and the tracker prints no
  "leaked semaphore" warning). A worker gone this way holds no pipe of the caller's any more,
  so ``lightcurve compare … | cat`` ends.
* :func:`stop_pool`: cancel what has not started and terminate (then kill) the workers of a
  ``ProcessPoolExecutor`` — used when a run is interrupted, instead of waiting for every
  running task to finish.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time

__all__ = ["Terminated", "handle_termination", "watch_parent", "stop_pool", "exit_code"]

_HANDLED = tuple(s for s in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None))
                 if s is not None)


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM or SIGHUP (``signum``); unwinds like Ctrl-C."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


def exit_code(exc: BaseException) -> int:
    """128 + signal number for an interruption (130 for Ctrl-C, 143 SIGTERM, 129 SIGHUP)."""
    return 128 + (exc.signum if isinstance(exc, Terminated) else int(signal.SIGINT))


@contextlib.contextmanager
def handle_termination():
    """Within the block, SIGTERM and SIGHUP raise :class:`Terminated` in the main thread.

    The first signal raises; later ones are ignored while the program unwinds (its clean-up
    is bounded: :func:`stop_pool` kills workers after a short grace period). Previous
    handlers are restored on exit. Outside the main thread this does nothing.

    Python runs a signal handler between any two bytecodes — also inside a finaliser or a
    weakref callback (Dask's client drops many weakrefs), where the exception it raises is
    only printed ("Exception ignored in ...") and the program goes on. Such a lost
    :class:`Terminated` (or Ctrl-C's ``KeyboardInterrupt``) reaches ``sys.unraisablehook``;
    the block's hook then delivers the signal again 50 ms later, from ordinary code, so a
    SIGTERM is never silently dropped (it used to be: ``compare --dask-local`` then ran to
    the end and exited 0). A re-delivery still pending when the block ends raises there.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    fired = []
    pending = []  # (timer, signum) of a re-delivery not yet run

    def on_signal(signum, frame):
        if fired:
            return
        fired.append(signum)
        raise Terminated(signum)

    def redeliver(signum):
        if pending:
            pending.clear()
            os.kill(os.getpid(), signum)

    old_hook = sys.unraisablehook

    def on_unraisable(unraisable):
        exc = unraisable.exc_value
        if isinstance(exc, KeyboardInterrupt):  # Terminated, or Ctrl-C's KeyboardInterrupt
            signum = exc.signum if isinstance(exc, Terminated) else int(signal.SIGINT)
            fired.clear()
            timer = threading.Timer(0.05, redeliver, (signum,))
            timer.daemon = True
            pending[:] = [(timer, signum)]
            timer.start()
            return
        old_hook(unraisable)

    old = {}
    for s in _HANDLED:
        with contextlib.suppress(OSError, ValueError):
            old[s] = signal.signal(s, on_signal)
    sys.unraisablehook = on_unraisable
    try:
        yield
    finally:
        late = list(pending)
        pending.clear()
        for timer, _ in late:
            timer.cancel()
        sys.unraisablehook = old_hook
        for s, h in old.items():
            with contextlib.suppress(OSError, ValueError, TypeError):
                signal.signal(s, h)
        if late and sys.exc_info()[0] is None:  # the block ended before the re-delivery
            signum = late[0][1]
            raise (Terminated(signum) if signum != signal.SIGINT else KeyboardInterrupt())


# ----------------------------------------------------------------------------------------
# workers
# ----------------------------------------------------------------------------------------
def _set_pdeathsig(sig) -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        return libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _exit_now(signum, frame=None) -> None:
    """SIGTERM handler of a worker: remove the temporary files of its writes in progress
    (:func:`lightcurve.io.atomic.remove_own_temp`), run the exit finalisers, then leave at once
    (a task in progress is abandoned; raising SystemExit would be caught by the pool's task
    loop)."""
    atomic = sys.modules.get("lightcurve.io.atomic")  # no import in a signal handler
    if atomic is not None:
        with contextlib.suppress(Exception):
            atomic.remove_own_temp()
    with contextlib.suppress(Exception):
        from multiprocessing import util

        util._exit_function()
    os._exit(128 + int(signum))


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _die(grace_s: float = 3.0) -> None:
    """SIGTERM to this process (graceful: :func:`_exit_now`), SIGKILL after ``grace_s``."""
    with contextlib.suppress(Exception):
        os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(grace_s)
    with contextlib.suppress(Exception):
        os.kill(os.getpid(), getattr(signal, "SIGKILL", signal.SIGTERM))
    os._exit(137)  # pragma: no cover - where SIGKILL is not available


def _watch(pid: int, poll_s: float) -> None:
    fd = None
    if hasattr(os, "pidfd_open"):
        try:
            fd = os.pidfd_open(pid)
        except ProcessLookupError:
            _die()
        except OSError:
            fd = None
    if fd is not None:
        import select

        while True:  # readable once the process has exited
            r, _, _ = select.select([fd], [], [])
            if r:
                _die()
    while _alive(pid):
        time.sleep(poll_s)
    _die()


def watch_parent(parent_pid: int, poll_s: float = 1.0, *, pdeathsig: bool = True) -> None:
    """Make this (worker) process die when process ``parent_pid`` dies (module docstring).

    ``pdeathsig=False`` skips the kernel's parent-death signal: it fires when the *thread*
    that forked this process exits, which is only safe where that thread lives as long as
    the pool (the forkserver's main thread; not an event-loop thread of Dask).
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _exit_now)
    if pdeathsig:
        _set_pdeathsig(signal.SIGTERM)
    if not _alive(parent_pid):  # died before the watch was set up
        _die()
    threading.Thread(target=_watch, args=(int(parent_pid), poll_s), daemon=True,
                     name="lightcurve-parent-watch").start()


def stop_pool(executor, grace_s: float = 2.0) -> None:
    """Stop a ``concurrent.futures.ProcessPoolExecutor`` now: cancel pending tasks, SIGTERM
    its workers, SIGKILL those still alive after ``grace_s``, reap them, and fail the tasks
    they were running (``BrokenProcessPool``)."""
    procs = list((getattr(executor, "_processes", None) or {}).values())
    # the executor forgets its manager thread on the first shutdown call: keep it, so that it
    # is joined before the tasks are failed here (else both set the same future's exception
    # and the thread dies with InvalidStateError, a traceback on stderr)
    manager = getattr(executor, "_executor_manager_thread", None)
    with contextlib.suppress(Exception):
        executor.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        with contextlib.suppress(Exception):
            p.terminate()
    end = time.monotonic() + grace_s
    for p in procs:
        with contextlib.suppress(Exception):
            p.join(max(0.0, end - time.monotonic()))
    for p in procs:
        with contextlib.suppress(Exception):
            if p.is_alive():
                p.kill()
                p.join(1.0)
    with contextlib.suppress(Exception):  # reap the executor's threads and queues now
        executor.shutdown(wait=True)
    if manager is not None and manager is not threading.current_thread():
        manager.join(5.0)
    # a task whose worker was killed is failed at once (the executor's own thread does this
    # asynchronously, and not at all when it had already left on the shutdown request)
    from concurrent.futures.process import BrokenProcessPool

    for item in list((getattr(executor, "_pending_work_items", None) or {}).values()):
        fut = getattr(item, "future", None)
        with contextlib.suppress(Exception):
            if fut is not None and not fut.done():
                fut.set_exception(BrokenProcessPool("the pool was stopped"))
