"""Suite-wide pytest configuration.

Physics-effect and diagnosis tests run the numba kernels single-threaded. Their data are small
(≲ 500 epochs): on a shared, oversubscribed 2-core machine the parallel thread pool costs far
more than it saves (measured: a 420-epoch facet sum 48 ms with the pool under load vs 0.05 ms on
one thread; the Earthshine scenario test 28 s vs 1 s; the diagnosis tests 5.2 min vs 1.7 min).
Results do not depend on the thread count: every output element of those kernels is computed on
its own.
"""

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
