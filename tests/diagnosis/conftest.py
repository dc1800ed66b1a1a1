"""Diagnosis tests run the numba kernels single-threaded.

Their data are small (≲ 500 epochs): on a shared, oversubscribed 2-core machine the parallel
thread pool costs far more than it saves (measured: a 420-epoch facet sum 48 ms with the pool
under load vs 0.05 ms on one thread; the diagnosis tests 5.2 min vs 1.7 min). Results do not
depend on the thread count: every output element of the kernels is computed on its own.
"""

import numba
import pytest


@pytest.fixture(autouse=True)
def _numba_one_thread():
    n = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(n)
