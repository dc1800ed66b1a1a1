"""Compile (or load from numba's on-disk cache) the hot kernels once, outside timed work.

Every numba kernel of the package is ``njit(cache=True)``: the first process that calls a
kernel compiles it and writes the machine code next to the module (``__pycache__``; numba
falls back to ``~/.cache/numba`` when the package folder is read-only); later processes load
it (no recompilation). :func:`warm_up` runs a tiny simulation and each attitude filter on it, so
that

* ``lightcurve warmup`` right after ``pip install`` pays the compilation once, before the first
  real command (the README install line does this);
* Monte Carlo workers call it once per process before timing runs, so a run's ``runtime_s``
  measures the filter, not the compiler or the cache load.
"""

from __future__ import annotations

import time
import warnings

__all__ = ["warm_up", "WARM_METHODS"]

WARM_METHODS = ("mekf", "ukf", "bpf")
_DONE: set = set()


def warm_up(methods=WARM_METHODS, *, dynamics=("controlled", "uncontrolled"),
            reflection=False, css=False) -> dict:
    """Run a 60 s, 12-epoch simulation of the thesis LEO case and invert it with ``methods``
    (BPF with 64 particles) under each filter ``dynamics`` model (the uncontrolled one uses
    other kernels: Euler's equations and their transition matrices); with ``reflection`` also
    the Model 3 facet-state filters; with ``css`` also a 60 s coarse-sun-sensor closed loop
    (the ``css simulate`` defaults: dual pyramid, tactical gyro, built-in albedo) for each of
    its estimators (:func:`_warm_css`).

    Idempotent per process (work already done returns at once). Returns ``{step: seconds}``.
    """
    from dataclasses import replace

    from ._paths import data_dir
    from .filters.invert import invert
    from .studies.scenario import load_scenario
    from .studies.simulate import simulate

    out = {}
    if css and ("css",) not in _DONE:
        t0 = time.perf_counter()
        _warm_css()
        out["css"] = time.perf_counter() - t0
        _DONE.add(("css",))
    todo = [(m, d) for m in methods for d in dynamics if (m, d, reflection) not in _DONE]
    if not todo:
        return out
    t0 = time.perf_counter()
    sc = load_scenario(data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml")
    sc = replace(sc, duration_s=60.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the thesis case ignores the eclipse on purpose
        lc = simulate(sc, seed=0)
    if ("simulate",) not in _DONE:
        out["simulate"] = time.perf_counter() - t0
        _DONE.add(("simulate",))
    for m, d in todo:
        t0 = time.perf_counter()
        kw = {"particles": 64} if m == "bpf" else {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            invert(lc, m, seed=0, dynamics=d, **kw)
            if reflection:
                invert(lc, m, seed=0, dynamics=d, reflection="model3", **kw)
        out[f"{m} {d}"] = time.perf_counter() - t0
        _DONE.add((m, d, reflection))
    return out


def _warm_css() -> None:
    """Compile the coarse-sun-sensor kernels: a 60 s closed loop of the ``css simulate``
    defaults (dual pyramid at 60° FOV, tactical gyro, built-in albedo in truth and filter, 0.5 s
    step) once per estimator in the loop (sun-line EKF, ECKF, WAVG, LSMN, WLSMN), and the
    gyro-less EKF."""
    from .css.configurations import configuration_by_name
    from .css.truth import CSSScenario, simulate_css

    sensors = configuration_by_name("dual_pyramid", fov_half_angle_deg=60.0)
    for est, gyro in (("ekf", "tactical"), ("eckf", "tactical"), ("wavg", "tactical"),
                      ("lsmn", "tactical"), ("wlsmn", "tactical"), ("ekf", None)):
        sc = CSSScenario(sensors, estimator=est, gyro=gyro, controlled=False, duration_s=60.0,
                         dt_s=0.5, epoch_utc="2015-03-01T00:00:00Z", albedo=None,
                         filter_albedo=None)
        simulate_css(sc, 0)
