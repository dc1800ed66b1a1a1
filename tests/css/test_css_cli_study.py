"""CLI (`lightcurve css simulate|estimate|study`), recordings and study TOML validation."""

import json

import numpy as np
import pytest

from lightcurve.cli import main
from lightcurve.css.recording import read_recording
from lightcurve.css.study import load_study, run_study, write_report
from lightcurve.errors import InputError


def test_cli_help_lists_css_commands(capsys):
    with pytest.raises(SystemExit) as e:
        main(["css", "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for cmd in ("simulate", "estimate", "study"):
        assert cmd in out


def test_cli_simulate_estimate_roundtrip(tmp_path, capsys):
    rec = tmp_path / "run.h5"
    # --filter-albedo none: CSS recordings carry no orbit positions, so the offline filter
    # runs without its albedo model; the in-loop filter must do the same to be comparable
    assert main(["css", "simulate", "--duration-s", "400", "--gyro", "tactical",
                 "--out", str(rec), "--seed", "3", "--filter-albedo", "none"]) == 0
    r = read_recording(rec)
    assert r["y"].shape == (801, 8) and r["gyro"].shape == (801, 3)
    # estimating offline with the same EKF reproduces the in-loop estimate
    out_csv = tmp_path / "est.csv"
    assert main(["css", "estimate", str(rec), "--estimator", "ekf", "--out", str(out_csv)]) == 0
    est = np.loadtxt(out_csv, delimiter=",", skiprows=1)
    import h5py

    with h5py.File(rec) as f:
        s_loop = f["estimate/s_hat"][()]
    assert np.allclose(est[:, 1:], s_loop, atol=1e-12)
    text = capsys.readouterr().out
    assert "99th percentile" in text


def test_cli_bad_inputs_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[[sensor]]\nnormal = [0, 0, 0]\n")
    assert main(["css", "simulate", "--config", str(bad), "--duration-s", "10"]) == 2
    assert "sensor[0].normal" in capsys.readouterr().err
    assert main(["css", "estimate", str(tmp_path / "missing.h5")]) == 2


def _study_toml(tmp_path, extra=""):
    p = tmp_path / "study.toml"
    p.write_text(f"""
[study]
name = "t"
n_runs = 2
seed = 3
settle_s = 60.0
[scenario]
configuration = "cube"
estimators = ["ekf", "lsmn"]
gyros = ["tactical"]
controlled = true
duration_s = 300.0
{extra}
[control]
deadband_deg = 2.0
""")
    return p


def test_study_load_run_report(tmp_path):
    spec = load_study(_study_toml(tmp_path))
    assert spec.control.deadband_rad == pytest.approx(np.radians(2.0))
    cases = run_study(spec)
    out = write_report(spec, cases, tmp_path / "rep")
    data = json.loads((out / "summary.json").read_text())
    assert [c["estimator"] for c in data["cases"]] == ["ekf", "lsmn"]
    assert (out / "envelopes.png").stat().st_size > 1000
    assert (out / "error_maps.png").stat().st_size > 1000
    assert "t_point" in (out / "summary.txt").read_text()


@pytest.mark.parametrize("extra,field", [
    ('albedo = "nowhere.csv"', ""),
    ('dt_s = -1.0', "scenario.dt_s"),
    ('estimaters = ["ekf"]', "scenario"),
])
def test_study_bad_toml(tmp_path, extra, field):
    with pytest.raises(InputError) as e:
        load_study(_study_toml(tmp_path, extra))
    assert field in str(e.value)


def test_bundled_study_files_load():
    from lightcurve._paths import data_dir

    files = sorted((data_dir("pipelines") / "css").glob("*.toml"))
    assert len(files) >= 3
    for f in files:
        spec = load_study(f)
        assert spec.n_runs == 1000


def test_read_recording_rejects_other_hdf5(tmp_path):
    import h5py

    p = tmp_path / "x.h5"
    with h5py.File(p, "w") as f:
        f["t"] = np.arange(3.0)
    with pytest.raises(InputError) as e:
        read_recording(p)
    assert "format" in str(e.value)
