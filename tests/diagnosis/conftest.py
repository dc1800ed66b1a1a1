"""Diagnosis tests: single-threaded BLAS (the fits' Jacobians are ≤ 2000 × 30; a
multi-threaded OpenBLAS spends most of its time synchronising threads on them —
measured 4× the CPU time on a loaded 2-core machine). Results do not depend on it."""

import pytest


@pytest.fixture(autouse=True, scope="session")
def _single_threaded_blas():
    from lightcurve.studies.runner import limit_blas_threads

    limit_blas_threads()
    yield
