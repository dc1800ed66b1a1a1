"""Thread budget: numba threads × worker processes ≤ the cores this process may use.

A study or batch inversion runs one filter per worker process, and the particle filter's
kernels are numba-parallel. Without a budget, W workers on C cores each start C numba threads
(W·C threads spinning against each other; measured on 2 cores, `--workers 2`: 4 threads). The
rules here:

* available cores = the CPU affinity mask (``os.sched_getaffinity``; ``os.cpu_count()`` where
  there is none), so a job confined by ``taskset``, cgroups or a batch scheduler is respected;
* a user's ``NUMBA_NUM_THREADS`` (set before lightcurve was imported) is an upper bound;
* W worker processes get ``max(1, cores // W)`` numba threads each (:func:`threads_per_worker`);
  a pool worker sets it at start (:func:`limit_numba_threads`), a Dask LocalCluster worker gets
  it in its environment, a task on another Dask cluster sets it for its own thread.

numba's threading layer is numba's choice (tbb, else omp, else workqueue; the user's
``NUMBA_THREADING_LAYER`` wins), with OpenMP's waiting threads made to spin briefly and then
sleep (:func:`configure_threading`, called on import of lightcurve). GNU OpenMP's default
spins for about 300,000 iterations (an effectively unbounded spin with
``OMP_WAIT_POLICY=ACTIVE``): on a busy machine spinning threads take the cores other
processes need, and a thread that sleeps at once (``OMP_WAIT_POLICY=PASSIVE``) pays a futex
wake-up at every one of the particle filter's ≈ 15 parallel regions per epoch. A bounded spin
of :data:`SPIN_COUNT` iterations (``GOMP_SPINCOUNT``) covers the short gaps between the regions
and then sleeps. OpenMP is kept rather than workqueue because workqueue aborts when two
Python threads launch parallel kernels at once (a Dask worker with several threads).
Measurements behind both choices: docs/bpf.md.
"""

from __future__ import annotations

import contextlib
import os

__all__ = ["available_cores", "user_thread_limit", "threads_per_worker", "limit_numba_threads",
           "limited_threads", "configure_threading"]

#: NUMBA_NUM_THREADS as the user set it before lightcurve was imported (None: not set)
_USER_LIMIT = os.environ.get("NUMBA_NUM_THREADS")


#: GNU OpenMP spin iterations before a waiting thread sleeps (``GOMP_SPINCOUNT``; module
#: docstring)
SPIN_COUNT = 3000


def configure_threading() -> str:
    """Make waiting OpenMP threads spin for :data:`SPIN_COUNT` iterations and then sleep
    (``GOMP_SPINCOUNT``), unless the user set ``OMP_WAIT_POLICY`` or ``GOMP_SPINCOUNT``;
    called on import of lightcurve, before numba loads its OpenMP layer (a later call has no
    effect on a runtime already loaded). Returns the setting in force, e.g.
    ``"GOMP_SPINCOUNT=3000"``."""
    if "OMP_WAIT_POLICY" in os.environ:
        return "OMP_WAIT_POLICY=" + os.environ["OMP_WAIT_POLICY"]
    return "GOMP_SPINCOUNT=" + os.environ.setdefault("GOMP_SPINCOUNT", str(SPIN_COUNT))


def available_cores() -> int:
    """Cores this process may run on (the affinity mask; ``os.cpu_count()`` without one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def user_thread_limit() -> int | None:
    """The user's NUMBA_NUM_THREADS (set before import) as an int ≥ 1, or None."""
    try:
        n = int(_USER_LIMIT) if _USER_LIMIT is not None else None
    except ValueError:
        return None
    return n if n is not None and n >= 1 else None


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    """numba threads for each of ``workers`` processes sharing ``cores`` (default: the
    affinity mask): ``max(1, cores // workers)``, capped by the user's NUMBA_NUM_THREADS."""
    c = available_cores() if cores is None else max(1, int(cores))
    n = max(1, c // max(1, int(workers)))
    u = user_thread_limit()
    return min(n, u) if u is not None else n


def limit_numba_threads(n: int) -> int:
    """Use at most ``n`` numba threads in this thread from now on. Returns the number set (never
    above numba's launch-time maximum). The environment is left alone: numba re-reads
    NUMBA_NUM_THREADS when it compiles and refuses a value changed after its threads started."""
    import numba

    n = max(1, min(int(n), int(numba.config.NUMBA_NUM_THREADS)))
    numba.set_num_threads(n)
    return n


@contextlib.contextmanager
def limited_threads(n: int):
    """Run the body with at most ``n`` numba threads in this thread (restored on exit)."""
    import numba

    old = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(n), old)))
    try:
        yield
    finally:
        numba.set_num_threads(old)
