"""The same study through the process pool, a 2-worker Dask LocalCluster and inline gives the
same summary.json numbers (seeds derive from the study seed and the cell, never the worker)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lightcurve.studies.runner import execute_task, read_run, run_study
from lightcurve.studies.study import load_study


def _numbers(path):
    """summary.json cells without the wall-clock runtime (the only executor-dependent field)."""
    doc = json.loads(path.read_text())
    for c in doc["cells"]:
        c.pop("runtime_s_median")
    return doc


def test_pool_and_dask_local_identical(tmp_path, study_file):
    pytest.importorskip("distributed", reason="the 'distributed' extra is not installed")
    study = load_study(study_file)
    a, b = tmp_path / "pool", tmp_path / "dask"
    run_study(study, a, workers=2, progress=False)
    run_study(study, b, dask_local=2, progress=False)
    na, nb = _numbers(a / "summary.json"), _numbers(b / "summary.json")
    assert na == nb
    assert [c["runs"] for c in na["cells"]] == [3, 3] and all(c["failures"] == 0 for c in na["cells"])
    # per-run arrays are bit-identical too
    for f in sorted((a / "runs").glob("*.h5")):
        ra, rb = read_run(f), read_run(b / "runs" / f.name)
        assert ra["status"] == rb["status"] == "ok"
        np.testing.assert_array_equal(ra["att_error_deg"], rb["att_error_deg"])
        np.testing.assert_array_equal(ra["omega_sigma_rad_s"], rb["omega_sigma_rad_s"])
    # and an inline re-execution of one task (this process) reproduces the stored run
    t = study.tasks()[4]
    r = execute_task(t)
    np.testing.assert_array_equal(r["att_error_deg"], read_run(a / "runs" / f"{t.run_id}.h5")["att_error_deg"])
    html = (a / "report.html").read_text()
    assert "data:image/png;base64," in html and 'class="fig94"' in html
    assert "<script" not in html and "http" not in html.replace("http-equiv", "")  # offline


def test_failures_recorded_and_study_goes_on(tmp_path, study_file, monkeypatch):
    """A run that raises is stored as failed (counted in 'failures'); the others finish."""
    import lightcurve.studies.runner as runner

    study = load_study(study_file)
    real = runner._lightcurve

    def flaky(text, file, r, seed, *rest):
        if seed == study.tasks()[1].sim_seed:
            raise RuntimeError("injected failure")
        return real(text, file, r, seed, *rest)

    monkeypatch.setattr(runner, "_lightcurve", flaky)
    s = run_study(study, tmp_path / "o", workers=1, progress=False, write_report=False)
    # run 1 of each cell shares the simulation seed (common random numbers): both fail
    assert [c["failures"] for c in s["cells"]] == [1, 1]
    assert [c["runs"] for c in s["cells"]] == [2, 2]
    bad = read_run(tmp_path / "o" / "runs" / f"{study.tasks()[1].run_id}.h5")
    assert bad["status"] == "failed" and "injected failure" in bad["error"]
    # the summary run_study builds from the runs it just made (kept in memory) equals the
    # summary of the stored files alone, failed runs included
    from lightcurve.studies.runner import summarize

    s_files = summarize(study, tmp_path / "o", write_report=False)
    assert json.dumps(s_files, sort_keys=True) == json.dumps(s, sort_keys=True)
    assert s["cells"][0]["runs"] == 2 and "first_error" in s["cells"][0]


def test_existing_scheduler_address(tmp_path, make_study):
    """``scheduler="tcp://…"`` sends the runs to an existing cluster: same numbers as inline."""
    distributed = pytest.importorskip("distributed", reason="the 'distributed' extra is not installed")
    study = load_study(make_study(tmp_path, filters=("ukf",), runs=2))
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        run_study(study, tmp_path / "remote", scheduler=cluster.scheduler_address,
                  progress=False, write_report=False)
    run_study(study, tmp_path / "inline", workers=1, progress=False, write_report=False)
    assert _numbers(tmp_path / "remote" / "summary.json") == _numbers(tmp_path / "inline" / "summary.json")


def test_missing_distributed_is_a_clear_error(tmp_path, study_file, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_dask(name, *a, **k):
        if name == "distributed" or name.startswith("distributed."):
            raise ImportError("No module named 'distributed'")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    from lightcurve.errors import InputError

    with pytest.raises(InputError, match=r"lightcurve\[distributed\]"):
        run_study(load_study(study_file), tmp_path / "o", dask_local=2, progress=False)
    with pytest.raises(InputError, match="choose one executor"):
        run_study(load_study(study_file), tmp_path / "o", dask_local=2, workers=2, progress=False)


def test_map_in_pool_keeps_the_order_and_counts_progress():
    # the CSS Monte Carlo loops (fault studies) use it: results in input order whatever the
    # completion order, one progress call per item, the same list in one process
    from lightcurve.studies.runner import map_in_pool

    calls = []
    xs = [-5, 3, -1, 0, 7, -2]
    assert map_in_pool(abs, xs, 2, progress=lambda: calls.append(1)) == [5, 3, 1, 0, 7, 2]
    assert len(calls) == len(xs)
    assert map_in_pool(abs, xs, 1) == [abs(x) for x in xs]
