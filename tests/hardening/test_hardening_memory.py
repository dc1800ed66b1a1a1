"""Small inputs that demand unbounded memory are refused before allocating, with a message
naming the estimate and the limit (lightcurve.memory); study tasks are generated lazily."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from lightcurve import InputError
from lightcurve._paths import data_dir
from test_hardening_special_files import run_cli


def test_memory_limit_setting(monkeypatch):
    from lightcurve.memory import check_allocation, memory_limit, parse_bytes

    assert parse_bytes("8GiB") == 8 * 1024**3 and parse_bytes("1.5G") == 1_500_000_000
    assert parse_bytes("512") == 512 and parse_bytes("none") is None
    for bad in ("lots", "-1G", "1 furlong", "nan"):
        with pytest.raises(InputError, match="LIGHTCURVE_MEMORY_LIMIT"):
            parse_bytes(bad)
    monkeypatch.setenv("LIGHTCURVE_MEMORY_LIMIT", "1MiB")
    assert memory_limit()[0] == 1024**2
    with pytest.raises(InputError, match=r"about 2\.0 MiB.*<= 1\.0 MiB"):
        check_allocation(2 * 1024**2, "a test array")
    assert check_allocation(1024, "a small array") == 1024
    monkeypatch.delenv("LIGHTCURVE_MEMORY_LIMIT")
    limit, why = memory_limit()
    assert limit is not None and limit > 0 and "physical" in why or "cgroup" in why


def test_convexity_check_of_a_large_facet_list_is_blocked(monkeypatch):
    """12,000 facets used to build a 12000x12000x3 array (3.2 GiB); blocks keep the peak
    below 200 MB, and the answer equals the plain all-pairs formula on small lists."""
    from lightcurve.photometry.facets import facets_convex

    rng = np.random.default_rng(1)
    for _ in range(20):  # independent all-pairs re-implementation on small random sets
        F = int(rng.integers(2, 40))
        n = rng.normal(size=(F, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        c = n * rng.uniform(0.9, 1.1, size=(F, 1)) if rng.random() < 0.5 else rng.normal(size=(F, 3))
        plain = all(n[i] @ (c[j] - c[i]) <= 1e-9 for i in range(F) for j in range(F) if i != j)
        assert facets_convex(n, c) == plain
    # a convex polyhedron with 12,000 facets: points on a sphere, normals = positions
    F = 12_000
    u = rng.normal(size=(F, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    tracemalloc.start()
    try:
        assert facets_convex(u, u)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 200e6, peak


def _scenario_text(duration_s, cadence_s):
    text = (data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml").read_text()
    return (text.replace("duration_s = 360.0", f"duration_s = {duration_s}")
            .replace("cadence_s = 5.0", f"cadence_s = {cadence_s}")
            .replace("windows_s = [[0.0, 360.0]]", f"windows_s = [[0.0, {duration_s}]]"))


def test_scenario_just_under_the_epoch_cap_is_refused_from_memory(monkeypatch, tmp_path):
    """4.3·10⁷ epochs (under the 5·10⁷ cap) need ~26 GB to simulate: refused at load,
    naming the epochs and the limit; under the limit the same schedule loads."""
    from lightcurve.studies.scenario import load_scenario

    p = tmp_path / "s.toml"
    p.write_text(_scenario_text(2_592_000.0, 0.06))
    monkeypatch.setenv("LIGHTCURVE_MEMORY_LIMIT", "16GiB")
    with pytest.raises(InputError) as ei:
        load_scenario(p)
    msg = str(ei.value)
    assert "simulating 43200001 epochs" in msg and "16.0 GiB" in msg and str(p) in msg
    monkeypatch.setenv("LIGHTCURVE_MEMORY_LIMIT", "none")
    assert load_scenario(p).cadence_s == 0.06


@pytest.mark.parametrize("argv, frag", [
    (["css", "simulate", "--duration-s", "31622400", "--dt-s", "0.001"],
     "CSS simulation of 31622400001 steps"),
    (["invert", "{lc}", "-o", "{out}", "--method", "bpf", "--particles", "10000000",
      "--workers", "1", "-q"], "particle filter with 10000000 particles"),
    (["fit-reflection", "{lc}", "-o", "{out}", "--walkers", "100000"],
     "MCMC with 100000 walkers"),
])
def test_huge_runs_refused_before_allocating(argv, frag, tmp_path, capsys, monkeypatch):
    from hardening_util import small_curve

    monkeypatch.setenv("LIGHTCURVE_MEMORY_LIMIT", "2GiB")
    lc = tmp_path / "lc.h5"
    small_curve().write(lc)
    tracemalloc.start()
    try:
        code, err = run_cli([a.format(lc=lc, out=tmp_path / "out") for a in argv], capsys)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert code == 2, err
    assert frag in err and "2.0 GiB" in err and "memory" in err, err
    assert peak < 500e6


def test_compare_with_a_million_runs_generates_tasks_lazily(tmp_path, monkeypatch):
    """`compare --runs 1000000` used to build every task first (760 MB after 75 s, nothing
    stored). Tasks are now generated as workers free up: the first runs are stored at once
    and the memory stays small."""
    import lightcurve.studies.runner as runner
    from lightcurve.studies.study import load_study
    from test_hardening_outputs import _write_study

    study = load_study(_write_study(tmp_path))
    calls = []
    real = runner.execute_task

    def few(task):
        if len(calls) == 5:
            raise KeyboardInterrupt
        calls.append(task.run_id)
        return real(task)

    monkeypatch.setattr(runner, "execute_task", few)
    tracemalloc.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            runner.run_study(study, tmp_path / "out", runs=1_000_000, workers=1,
                             progress=False, write_report=False)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(calls) == 5
    assert len(list((tmp_path / "out" / "runs").glob("*.h5"))) == 5
    assert peak < 100e6, peak


def test_lazy_tasks_equal_the_sorted_task_list(tmp_path):
    """iter_tasks yields exactly tasks(), in the order the runner used to sort them into
    (scenario key, run index; grid order inside)."""
    from lightcurve.studies.study import load_study
    from test_hardening_outputs import _write_study

    text = _write_study(tmp_path).read_text().replace('filter = ["ukf", "mekf"]',
                                                      'filter = ["ukf", "mekf", "bpf"]')
    (tmp_path / "study.toml").write_text(text.replace("r_percent = [1.0]",
                                                      "r_percent = [1.0, 3.0]"))
    extra = tmp_path / "extra"
    extra.mkdir()
    study = load_study(tmp_path / "study.toml", library_dirs=[extra], site_dirs=[extra])
    ref = sorted(study.tasks(4), key=lambda t: (t.cell.scenario_key, t.run))
    lazy = list(study.iter_tasks(4))
    assert lazy == ref and len(lazy) == 3 * 2 * 4
    assert all(t.library_dirs == (str(extra.resolve()),) and t.site_dirs for t in lazy)
