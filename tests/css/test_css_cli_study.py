"""CLI (`lightcurve css simulate|estimate|study`), recordings and study TOML validation."""

import json

import numpy as np
import pytest

from lightcurve.cli import main
from lightcurve.css.recording import read_css_recording
from lightcurve.css.study import load_css_study, run_css_study
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
    r = read_css_recording(rec)
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
experiment = "fig3_11"
runs = 2
seed = 3
settle_s = 60.0
[scenario]
configuration = "cube"
estimators = ["ekf", "lsmn"]
variants = ["thesis", "robust"]
gyros = ["intermediate"]
controlled = true
duration_s = 300.0
albedo = "builtin"
{extra}
""")
    return p


def _with_section(tmp_path, text):
    """The test study without and with ``text`` (a TOML section) appended: (base spec, spec,
    path of the file with the section)."""
    base = load_css_study(_study_toml(tmp_path))
    p = _study_toml(tmp_path)
    p.write_text(p.read_text() + "\n" + text)
    return base, load_css_study(p), p


def test_study_load_run_resume_report(tmp_path, capsys):
    spec = load_css_study(_study_toml(tmp_path))
    assert spec.estimators == ("ekf", "lsmn") and spec.variants == ("thesis", "robust")
    out = tmp_path / "rep"
    # the CLI: -o/--output and the deprecated --out alias, one worker (inline)
    assert main(["css", "study", str(_study_toml(tmp_path)), "--workers", "1", "-q",
                 "--out", str(out)]) == 0
    data = json.loads((out / "summary.json").read_text())
    assert [(c["estimator"], c["variant"]) for c in data["cases"]] == [
        ("ekf", "thesis"), ("lsmn", "thesis"), ("ekf", "robust"), ("lsmn", "robust")]
    assert all(c["runs"] == 2 for c in data["cases"])
    # the right thesis number for this experiment (fig. 3.11: controlled EKF 4 deg)
    assert data["cases"][0]["thesis_p99_deg"] == 4.0
    html = (out / "report.html").read_text()
    assert "Verdict:" in html and "data:image/png;base64," in html
    assert data["verdict"]["level"] in ("ok", "warn") and "thesis variant" in data["verdict"]["text"]
    runs = sorted(p.name for p in (out / "runs").glob("*.npz"))
    assert len(runs) == 2 * 2 * 2  # controlled: one task per run, variant and estimator
    mtimes = {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*.npz")}
    # resume: nothing recomputed, more runs only adds the missing ones
    summary = run_css_study(spec, out, runs=3, workers=1, progress=False)
    assert all(c["runs"] == 3 for c in summary["cases"])
    # the NEES of the sun-line filter: mean over runs and the median run, from the per-run
    # means stored with each run (NaN, and left out, for a run without settled samples)
    per_run = []
    for f in sorted((out / "runs").glob("*_ekf.npz")):
        m = json.loads(bytes(np.load(f)["meta"]).decode())
        if "_thesis_" in f.name:
            per_run.append(next(iter(m["scalars"].values()))["nees_mean"])
    ekf = summary["cases"][0]
    per_run = [v for v in per_run if np.isfinite(v)]
    assert per_run
    assert np.isclose(ekf["nees_mean"], np.mean(per_run))
    assert np.isclose(ekf["nees_run_median"], np.median(per_run))
    for name, mt in mtimes.items():
        assert (out / "runs" / name).stat().st_mtime_ns == mt
    # a different study in the same folder is refused (exit 2), unless --force
    other = _study_toml(tmp_path, "")
    other.write_text(other.read_text().replace("seed = 3", "seed = 4"))
    assert main(["css", "study", str(other), "--workers", "1", "-q", "-o", str(out)]) == 2
    assert "different study" in capsys.readouterr().err


def test_study_bad_toml(tmp_path):
    p = _study_toml(tmp_path)
    p.write_text(p.read_text().replace('estimators = ["ekf", "lsmn"]', 'estimators = ["kalman"]'))
    with pytest.raises(InputError, match="scenario.estimators"):
        load_css_study(p)


@pytest.mark.parametrize("extra,field", [
    ('albedo = "nowhere.csv"', "scenario.albedo"),
    ('duration_s = -1.0', "scenario.duration_s"),
    ('estimaters = ["ekf"]', "scenario"),
])
def test_study_bad_fields(tmp_path, extra, field):
    with pytest.raises(InputError) as e:
        load_css_study(_rewrite(tmp_path, extra))
    assert field in str(e.value)


def _rewrite(tmp_path, extra):
    p = _study_toml(tmp_path)
    p.write_text(p.read_text().replace('albedo = "builtin"\n', "").replace(
        "duration_s = 300.0\n", "" if "duration_s" in extra else "duration_s = 300.0\n") + "")
    txt = p.read_text().replace("[scenario]\n", "[scenario]\n" + extra + "\n")
    p.write_text(txt)
    return p


def test_bundled_study_files_load():
    # every O'Keefe experiment file loads, cites its experiment and runs the thesis's 1000 cases
    from lightcurve._paths import data_dir
    from lightcurve.css.okeefe2015 import THESIS_RESULTS

    files = sorted((data_dir("pipelines") / "css" / "okeefe2015").glob("*.toml"))
    assert len(files) >= 6
    for f in files:
        spec = load_css_study(f)
        assert spec.runs == 1000 and spec.experiment in THESIS_RESULTS
        assert spec.simulation["fov_half_angle_deg"] == 60.0
        assert spec.simulation["noise_sigma"] == 0.05


def test_read_recording_rejects_other_hdf5(tmp_path):
    import h5py

    p = tmp_path / "x.h5"
    with h5py.File(p, "w") as f:
        f["t"] = np.arange(3.0)
    with pytest.raises(InputError) as e:
        read_css_recording(p)
    assert "format" in str(e.value)


def test_study_thesis_filter_override(tmp_path):
    # [thesis_filter]: one thesis-filter parameter switched for a measured ablation; it reaches
    # the thesis filters only, changes the study hash, and a study without it keeps its hash
    from lightcurve.css.study import scenario_for
    from lightcurve.css.sunline_thesis import THESIS_PRM

    base, spec, _ = _with_section(tmp_path, "[thesis_filter]\nsigma_valpha = 0.2\n")
    assert spec.thesis_filter == {"sigma_valpha": 0.2} and base.thesis_filter == {}
    assert spec.hash != base.hash
    i = THESIS_PRM.index("sigma_valpha")
    th = scenario_for(spec, "eckf", "thesis", "intermediate")
    assert th.thesis_params[i] == 0.2
    # O'Keefe §3.2.3's σ_Vα = 0.1 stays the default of the thesis ECKF
    assert scenario_for(base, "eckf", "thesis", "intermediate").thesis_params[i] == 0.1
    # a study file without the section hashes as before the section existed
    import hashlib
    from dataclasses import asdict

    d = asdict(base)
    for k in ("runs", "text", "source", "thesis_filter", "robust_filter", "gyroless"):
        d.pop(k)
    assert base.hash == hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()
                                       ).hexdigest()


@pytest.mark.parametrize("section,extra,field", [
    ("thesis_filter", "sigma_valfa = 0.2", "thesis_filter.sigma_valfa"),
    ("thesis_filter", "kind = 1.0", "thesis_filter.kind"),
    ("thesis_filter", "sigma_valpha = -0.1", "thesis_filter.sigma_valpha"),
    ("robust_filter", "fov_modell = true", "robust_filter.fov_modell"),
    ("robust_filter", "fov_model = 1.5", "robust_filter.fov_model"),
    ("robust_filter", "albedo_sigma = -0.1", "robust_filter.albedo_sigma"),
])
def test_study_filter_overrides_bad(tmp_path, section, extra, field):
    p = _study_toml(tmp_path)
    p.write_text(p.read_text() + f"\n[{section}]\n{extra}\n")
    with pytest.raises(InputError) as e:
        load_css_study(p)
    assert field in str(e.value)


def test_every_thesis_filter_parameter_can_be_overridden(tmp_path):
    # every sun-line thesis-filter parameter except the filter selector "kind" is accepted
    from lightcurve.css.sunline_thesis import THESIS_PRM

    for k in THESIS_PRM:
        if k == "kind":
            continue
        p = _study_toml(tmp_path)
        p.write_text(p.read_text() + f"\n[thesis_filter]\n{k} = 0.5\n")
        assert load_css_study(p).thesis_filter == {k: 0.5}, k


def test_bundled_ablation_files_differ_by_one_switch():
    # each ablation is its experiment's file with one change (same seeds, orbit, sensors)
    from lightcurve._paths import data_dir

    d = data_dir("pipelines") / "css" / "okeefe2015"
    refs = {r.experiment: r for r in map(load_css_study, d.glob("fig3_*.toml"))}
    files = sorted((d / "ablations").glob("*.toml"))
    assert files
    for f in files:
        a = load_css_study(f)
        ref = refs[a.experiment]
        assert a.name.startswith("ablation-") and f.name.startswith(a.experiment)
        assert (a.seed, a.settle_s, a.configuration, a.controlled, a.duration_s, a.gyros) == (
            ref.seed, ref.settle_s, ref.configuration, ref.controlled, ref.duration_s,
            ref.gyros), f.name
        assert a.simulation == ref.simulation
        changes = ((a.albedo != ref.albedo) + bool(a.thesis_filter) + bool(a.robust_filter)
                   + bool(a.gyroless))
        assert changes == 1, f.name
        assert len(a.thesis_filter) + len(a.robust_filter) + len(a.gyroless) <= 1, f.name


def test_run_task_interruption_inside_kernel_is_not_a_failed_run(tmp_path, monkeypatch):
    # SIGTERM/Ctrl-C while a numba kernel runs reaches Python as a SystemError caused by the
    # interruption; it must stop the study, not be stored as a failed run (a resumed study
    # skips stored runs, so that run would stay "failed" for good)
    import lightcurve.css.truth as truth
    from lightcurve.css.study import run_task, study_tasks
    from lightcurve.process import Terminated

    def interrupted(*a, **k):
        try:
            raise Terminated(15)
        except Terminated as t:
            raise SystemError("CPUDispatcher(truth_loop_nb) returned a result with an "
                              "exception set") from t

    def broken(*a, **k):
        raise SystemError("some other failure")

    task = study_tasks(load_css_study(_study_toml(tmp_path)), 1)[0]
    monkeypatch.setattr(truth, "simulate_css_cases", interrupted)
    with pytest.raises(Terminated):
        run_task(task)
    monkeypatch.setattr(truth, "simulate_css_cases", broken)
    res = run_task(task)
    assert res["status"] == "failed" and "some other failure" in res["error"]


def test_study_robust_filter_override(tmp_path):
    # [robust_filter]: FilterParams fields of our sun-line filters, with their types; they reach
    # the robust variant only and change the study hash
    from lightcurve.css.study import scenario_for

    base, spec, _ = _with_section(tmp_path, "[robust_filter]\nfov_model = false\n"
                                  "albedo_n_phi = 24\nalbedo_sigma = 0.05\n")
    assert spec.robust_filter == {"fov_model": False, "albedo_n_phi": 24, "albedo_sigma": 0.05}
    assert base.robust_filter == {} and spec.hash != base.hash
    rob = scenario_for(spec, "ekf", "robust", "intermediate").filter_params
    assert rob.fov_model is False and rob.albedo_n_phi == 24 and rob.albedo_sigma == 0.05
    assert scenario_for(base, "ekf", "robust", "intermediate").filter_params.fov_model is True
    assert scenario_for(spec, "ekf", "thesis", "intermediate").filter_params.fov_model is True


def test_study_gyroless_override_reaches_the_thesis_variant_only(tmp_path):
    # [gyroless]: the thesis variant's §3.3.3 rate processing (okeefe2015.GYROLESS names) for
    # measured ablations; it changes the hash, is recorded, and a bad key or value is refused
    # with the file and the field named
    from lightcurve.css.okeefe2015 import GYROLESS
    from lightcurve.css.study import scenario_for

    base, spec, p = _with_section(tmp_path, "[gyroless]\nlowpass_hz = 0.1\n")
    assert spec.gyroless == {"lowpass_hz": 0.1} and base.gyroless == {}
    assert spec.hash != base.hash
    th = scenario_for(spec, "ekf", "thesis", "none").gyroless
    assert th["lowpass_hz"] == 0.1 and th["rate_limit_deg_s"] == GYROLESS["rate_limit_deg_s"]
    assert scenario_for(spec, "ekf", "robust", "none").gyroless["lowpass_hz"] == 10.0
    assert scenario_for(base, "ekf", "thesis", "none").gyroless["lowpass_hz"] == 10.0
    for bad, field in (("lowpass = 0.1", "gyroless.lowpass"), ("lowpass_hz = -1.0",
                                                               "gyroless.lowpass_hz")):
        p.write_text(_study_toml(tmp_path).read_text() + f"\n[gyroless]\n{bad}\n")
        with pytest.raises(InputError, match=field.replace(".", r"\.")) as e:
            load_css_study(p)
        assert str(p) in str(e.value)


def test_study_gyroless_cases_take_the_gyroless_tuning(tmp_path):
    # a robust case without gyro runs with sunline_ekf.gyroless_params (the tuning of
    # `lightcurve css simulate --gyro none`), not the gyro tuning; [robust_filter] overrides
    # apply on top of it
    from lightcurve.css.study import scenario_for
    from lightcurve.css.sunline_ekf import FilterParams, gyroless_params

    base = load_css_study(_study_toml(tmp_path))
    assert scenario_for(base, "ekf", "robust", "none").filter_params == gyroless_params()
    assert scenario_for(base, "ekf", "robust", "intermediate").filter_params == FilterParams()
    assert gyroless_params() != FilterParams()
    p = _study_toml(tmp_path)
    p.write_text(p.read_text() + "\n[robust_filter]\nfov_model = false\n")
    rob = scenario_for(load_css_study(p), "ekf", "robust", "none").filter_params
    assert rob.fov_model is False and rob.q_proc == gyroless_params().q_proc



def test_study_refuses_toms_albedo_without_the_data(tmp_path, monkeypatch):
    # a study that names the §2.1.2.1 TOMS albedo must not silently run with the built-in
    # zonal model: without the data folder the study file is refused (exit 2) before any run
    # is written; the same file with albedo = "builtin" loads
    from lightcurve.css import experiments

    monkeypatch.setenv("LIGHTCURVE_SHARED_DATA", str(tmp_path / "absent"))
    monkeypatch.setattr(experiments, "_TOMS_CACHE", {})
    p = _study_toml(tmp_path)
    p.write_text(p.read_text().replace('albedo = "builtin"', 'albedo = "toms"'))
    with pytest.raises(InputError) as e:
        load_css_study(p)
    msg = str(e.value)
    assert "scenario.albedo" in msg and "toms" in msg and str(p) in msg
    out = tmp_path / "out"
    assert main(["css", "study", str(p), "-q", "-o", str(out)]) == 2
    assert not (out / "runs").exists()
    p.write_text(p.read_text().replace('albedo = "toms"', 'albedo = "builtin"'))
    assert load_css_study(p).albedo == "builtin"
    # the API path warns instead
    with pytest.warns(RuntimeWarning, match="TOMS albedo grid 1p25x1 not available"):
        assert experiments.thesis_albedo("1p25x1") is None
