"""Batch inversion (`lightcurve invert` with many files and globs).

The same two lightcurves inverted inline, with the process pool and with a 2-worker Dask
LocalCluster give bit-identical estimates (each file's filter is seeded with --seed alone, so
nothing depends on the executor); patterns are expanded by us (a quoted glob works, one that
matches nothing is an error naming it); a failing file is recorded and the others finish.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from lightcurve.cli import main
from lightcurve.errors import InputError
from lightcurve.filters.result import read_estimate
from lightcurve.studies.batch import expand_inputs, invert_files
from lightcurve.studies.scenario import parse_scenario
from lightcurve.studies.simulate import simulate


@pytest.fixture
def two_files(tmp_path, make_study):
    """Two simulated 13-epoch lightcurves (the tiny controlled scenario of conftest.py)."""
    d = tmp_path / "in"
    d.mkdir()
    make_study(d)
    scen = d / "tiny-controlled-1site.toml"
    sc = parse_scenario(scen.read_text(), file=scen)
    paths = []
    for i in range(2):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the tiny scenario ignores the eclipse on purpose
            lc = simulate(sc, seed=100 + i)
        paths.append(Path(lc.write(d / f"lc{i}.h5")))
    return d, paths


_ARRAYS = ("t", "q", "omega_rad_s", "cov", "att_sigma_deg", "att_error_deg", "nees", "flags")


def _numbers(summary):
    out = {}
    for k, v in summary.items():
        v = dict(v)
        for f in ("runtime_s", "result", "file"):
            v.pop(f, None)
        out[k] = v
    return out


def test_inline_pool_and_dask_identical(two_files, tmp_path):
    pytest.importorskip("distributed", reason="the 'distributed' extra is not installed")
    d, _ = two_files
    pattern = str(d / "lc*.h5")
    runs = {}
    for name, kw in (("inline", {"workers": 1}), ("pool", {"workers": 2}),
                     ("dask", {"dask_local": 2})):
        res = invert_files([pattern], "ukf", tmp_path / name, progress=False, seed=5,
                           sigma_theta_deg=3.0, **kw)
        assert res["n_files"] == 2 and res["n_failed"] == 0
        runs[name] = res["summary"]
    assert list(runs["inline"]) == ["lc0", "lc1"]  # input (sorted glob) order
    ref = _numbers(runs["inline"])
    assert _numbers(runs["pool"]) == ref and _numbers(runs["dask"]) == ref
    for key in ("lc0", "lc1"):
        a = read_estimate(tmp_path / "inline" / f"{key}.ukf.h5")
        for name in ("pool", "dask"):
            b = read_estimate(tmp_path / name / f"{key}.ukf.h5")
            for arr in _ARRAYS:
                np.testing.assert_array_equal(getattr(a, arr), getattr(b, arr), err_msg=f"{name} {arr}")
    # the two files are different lightcurves (the comparison above is not trivially equal)
    assert not np.array_equal(read_estimate(tmp_path / "inline" / "lc0.ukf.h5").q,
                              read_estimate(tmp_path / "inline" / "lc1.ukf.h5").q)


def test_glob_expansion_and_unmatched_pattern(two_files, tmp_path, capsys):
    d, paths = two_files
    got = expand_inputs([str(d / "lc?.h5"), str(paths[0])])  # duplicate dropped
    assert [p.name for p in got] == ["lc0.h5", "lc1.h5"]
    with pytest.raises(InputError) as ei:
        expand_inputs([str(d / "nothing*.h5")])
    assert "nothing*.h5" in str(ei.value) and "matches no file" in str(ei.value)
    # through the CLI: the quoted pattern is expanded here; a pattern matching nothing → exit 2
    rc = main(["invert", str(d / "*.h5"), "--method", "ukf", "--workers", "1", "-q",
               "-o", str(tmp_path / "o")])
    assert rc == 0
    summ = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert set(summ) == {"lc0", "lc1"}
    capsys.readouterr()
    rc = main(["invert", str(d / "zz*.h5"), "-o", str(tmp_path / "o2")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "zz*.h5" in err and "matches no file" in err


def test_failed_file_recorded_others_finish(two_files, tmp_path, monkeypatch, capsys):
    d, paths = two_files
    corrupt = tmp_path / "corrupt.h5"
    corrupt.write_bytes(paths[0].read_bytes()[:600])
    # a bad input file: recorded with its error, the good file finishes, exit code 2
    rc = main(["invert", str(corrupt), str(paths[1]), "--workers", "2", "-q",
               "-o", str(tmp_path / "a")])
    assert rc == 2
    summ = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summ["corrupt"]["error_kind"] == "input" and "corrupt.h5" in summ["corrupt"]["error"]
    assert summ["lc1"]["final_att_error_rss_deg"] >= 0 and (tmp_path / "a" / "lc1.ukf.h5").exists()
    # a run-time failure (injected, inline so the patch applies): recorded, exit code 1
    inv_mod = sys.modules["lightcurve.filters.invert"]
    real = inv_mod.invert

    def boom(curve, method, **kw):
        if len(curve.t) and curve.mag[0] == read_estimate_first_mag(paths[0]):
            raise RuntimeError("injected failure")
        return real(curve, method, **kw)

    monkeypatch.setattr(inv_mod, "invert", boom)
    capsys.readouterr()
    rc = main(["invert", str(paths[0]), str(paths[1]), "--workers", "1", "-q",
               "-o", str(tmp_path / "b")])
    assert rc == 1
    summ = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert summ["lc0"]["error_kind"] == "runtime" and "injected failure" in summ["lc0"]["error"]
    assert "final_att_error_rss_deg" in summ["lc1"]
    assert "lightcurve: failed:" in capsys.readouterr().err


def read_estimate_first_mag(path):
    from lightcurve.io.lightcurve_h5 import read_lightcurve

    return read_lightcurve(path).mag[0]


def test_colliding_stems_get_distinct_outputs(two_files, tmp_path):
    d, paths = two_files
    sub = tmp_path / "other"
    sub.mkdir()
    (sub / "lc0.h5").write_bytes(paths[1].read_bytes())
    res = invert_files([str(paths[0]), str(sub / "lc0.h5")], "ukf", tmp_path / "o",
                       workers=1, progress=False)
    assert list(res["summary"]) == ["lc0", "lc0-2"]
    assert (tmp_path / "o" / "lc0.ukf.h5").exists() and (tmp_path / "o" / "lc0-2.ukf.h5").exists()
