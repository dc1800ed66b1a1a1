"""Suite-wide pytest configuration.

Physics-effect and diagnosis tests run the numba kernels single-threaded. Their data are small
(≲ 500 epochs): on a shared, oversubscribed 2-core machine the parallel thread pool costs far
more than it saves (measured: a 420-epoch facet sum 48 ms with the pool under load vs 0.05 ms on
one thread; the Earthshine scenario test 28 s vs 1 s; the diagnosis tests 5.2 min vs 1.7 min).
Results do not depend on the thread count: every output element of those kernels is computed on
its own.
"""

import os
import signal
import subprocess
import sys
from pathlib import Path

import numba
import pytest

SINGLE_THREAD_DIRS = ("physics", "diagnosis")
_HERE = Path(__file__).resolve().parent


def _top_dir(path):
    try:
        return Path(str(path)).resolve().relative_to(_HERE).parts[0]
    except ValueError:
        return None


@pytest.fixture(autouse=True)
def _numba_one_thread_where_small(request):
    """Limit numba's thread pool to one thread for tests under SINGLE_THREAD_DIRS."""
    if _top_dir(request.node.path) not in SINGLE_THREAD_DIRS:
        yield
        return
    n = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(n)


# --- compiling the slowest kernels on a second core -----------------------------------------
# With a cold numba cache about 40 % of the suite's time is compilation, most of it in a few large
# kernels, while the tests themselves mostly run on one core. Once a session has collected its
# tests, a second process (tests/_precompile.py, one numba thread) compiles those kernels into
# numba's on-disk cache; a test that needs one later loads it instead of compiling it. Results are
# unchanged (the cache holds the same machine code either process would compile). Only for
# sessions of at least PRECOMPILE_MIN_TESTS tests (a few tests need few kernels); off with
# LIGHTCURVE_TEST_PRECOMPILE=0, and on a machine with fewer than two usable cores.
_PRECOMPILE = []
PRECOMPILE_MIN_TESTS = 200


def pytest_collection_finish(session):
    from lightcurve.threads import available_cores

    if os.environ.get("LIGHTCURVE_TEST_PRECOMPILE", "1") == "0" or available_cores() < 2:
        return
    if len(session.items) < PRECOMPILE_MIN_TESTS or _PRECOMPILE:
        return
    if os.environ.get("PYTEST_XDIST_WORKER"):
        return
    import lightcurve

    pkg_parent = str(Path(lightcurve.__file__).resolve().parents[1])
    env = dict(os.environ, NUMBA_NUM_THREADS="1", LIGHTCURVE_PRECOMPILE_PATH=pkg_parent)
    _PRECOMPILE.append(subprocess.Popen(
        [sys.executable, str(_HERE / "_precompile.py")], stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, start_new_session=True))


def pytest_sessionfinish(session, exitstatus):
    for p in _PRECOMPILE:
        if p.poll() is None:  # still compiling what the suite no longer needs
            try:
                os.killpg(p.pid, signal.SIGTERM)
                p.wait(timeout=10)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                p.kill()
    _PRECOMPILE.clear()
