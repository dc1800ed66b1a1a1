"""The remaining exit codes: inputs that used to fail with exit 1 ("failed: <Type>") or pass
the option checks and fail later are bad input — exit 2 with one line naming the file or
option — and the filters' input boundary (magnitude range, geometry) plus the smaller defects
of the hostile review.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from hardening_util import small_curve
from lightcurve import InputError
from lightcurve._paths import data_dir
from test_hardening_special_files import run_cli

#: the thesis LEO fast-spin case (Bernard §9.3), the edited base of the scenario cases
DEFAULT = (data_dir("pipelines") / "thesis" / "leo-ic1-fast-spin-controlled-1site.toml").read_text()
#: its [[sites]] table (one Socorro entry), as written in the file
_SITE = DEFAULT[DEFAULT.index("[[sites]]"):DEFAULT.index("[measurement]")]


def _scenario(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def one_line(err):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("lightcurve: error:"), err
    return lines[0]


# ----------------------------------------------------------------------------------------
# scenario and study files
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("edit, frag", [
    (lambda t: t + "\nx = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply"),
    (lambda t: t.replace('"2020-03-01T08:08:40Z"', '"0001-01-01T00:00:00+01:00"'),
     "scenario.epoch_utc"),
    (lambda t: t.replace("seed = 1", "seed = 1000000000000000000000000000000"), "scenario.seed"),
    (lambda t: t.replace("a_km = 6871.14", "a_km = 1e300"), "orbit.a_km"),
    (lambda t: t.replace("acs_sigma_deg = 0.1", "acs_sigma_deg = 0.1\ninertia_kg_m2 = "
                         "[[1e308, 0, 0], [0, 1e308, 0], [0, 0, 1e308]]"),
     "attitude.inertia_kg_m2"),
    (lambda t: t.replace("windows_s = [[0.0, 360.0]]", "windows_s = [[0.0, inf]]"),
     "finite seconds"),
    (lambda t: t.replace(_SITE, _SITE * 1000), "two [[sites]] entries with one id"),
    (lambda t: t.replace(_SITE, _SITE + '[[sites]]\nid = "socorro-again"\nlat_deg = 33.8173\n'
                         'lon_deg = -106.66\nheight_m = 1500.0\nwindows_s = [[0.0, 360.0]]\n'),
     "the same place as sites[0]"),
])
def test_scenario_inputs_exit_2(edit, frag, tmp_path, capsys):
    p = _scenario(tmp_path, edit(DEFAULT))
    assert p.read_text() != DEFAULT
    code, err = run_cli(["simulate", p, "-o", tmp_path / "o.h5"], capsys)
    assert code == 2, err
    line = one_line(err)
    assert frag in line and str(p) in line
    assert not (tmp_path / "o.h5").exists()


def test_shape_inertia_too_large_exit_2(tmp_path, capsys):
    cube = (data_dir("shapes") / "cube_1u.toml").read_text()
    import re

    text = re.sub(r"inertia_(diag_)?kg_m2 = .*", "inertia_diag_kg_m2 = [1e308, 1e308, 1e308]",
                  cube, count=1)
    assert text != cube
    p = _scenario(tmp_path, text, "cube.toml")
    code, err = run_cli(["shapes", "validate", p], capsys)
    assert code == 2 and "inertia element too large" in err, err


def test_nested_toml_inside_an_hdf5_file_exit_2(tmp_path, capsys):
    """`diagnose file.h5` parses the scenario stored in the file: 5,000-deep nesting there
    was a RecursionError (exit 1)."""
    lc = small_curve()
    lc.scenario_toml = DEFAULT + "\nx = " + "[" * 5000 + "]" * 5000 + "\n"
    f = tmp_path / "deep.h5"
    lc.write(f)
    code, err = run_cli(["diagnose", f, "-o", tmp_path / "dg"], capsys)
    assert code == 2 and "nested too deeply" in one_line(err) and str(f) in err


@pytest.mark.parametrize("template, frag", [
    ("tiny-{dynamics.nope}-{sites}site.toml", "unknown placeholder"),
    ("tiny-{dynamics}-{sites:>300}site.toml", "format spec"),
    ("tiny-{dynamics!r}-{sites}site.toml", "format spec or conversion"),
    ("tiny-{0}-{sites}site.toml", "unknown placeholder"),
])
def test_study_template_placeholders_exit_2(template, frag, tmp_path, capsys):
    from test_hardening_outputs import _write_study

    study = _write_study(tmp_path)
    study.write_text(study.read_text().replace("tiny-{dynamics}-{sites}site.toml", template))
    code, err = run_cli(["compare", study, "-o", tmp_path / "o", "--workers", "1"], capsys)
    assert code == 2 and frag in one_line(err) and "study.scenario" in err, err


def test_csv_field_over_the_csv_module_limit(tmp_path):
    from lightcurve.io.recording import read_recording

    p = tmp_path / "rec.csv"
    p.write_text("time_utc,mag,site\n2020-03-01T08:08:40Z,7.0,socorro\n"
                 f"2020-03-01T08:08:45Z,\"{'9' * 140_000}\",socorro\n")
    with pytest.raises(InputError, match=r"line 3.*field larger than field limit"):
        read_recording(p)


# ----------------------------------------------------------------------------------------
# command-line options that passed their checks and failed later
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("opt, value", [
    ("--alpha", "1e-300"), ("--alpha", "2"), ("--kappa", "-6"), ("--beta", "-1"),
    ("--beta", "1e308"), ("--kappa", "1e308"), ("--sigma-omega-deg-s", "1e308"),
    ("--roughening", "1e308"), ("--pseudo-noise", "1e308"), ("--reflection-frac", "1e308"),
])
def test_filter_options_out_of_range_exit_2(opt, value, tmp_path, capsys):
    lc = tmp_path / "lc.h5"
    small_curve().write(lc)
    code, err = run_cli(["invert", lc, "-o", tmp_path / "o", opt, value], capsys)
    assert code == 2 and "out of range" in err and opt in err, err
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------------------
# filters: the input boundary
# ----------------------------------------------------------------------------------------
def _h5_with(tmp_path, **changes):
    lc = small_curve()
    for k, v in changes.items():
        setattr(lc, k, v)
    import h5py

    p = tmp_path / "bad.h5"
    small_curve().write(p)
    with h5py.File(p, "r+") as h:  # write the hostile values past the writer's validation
        for k, v in changes.items():
            name = {"mag": "mag", "r_obj_eci_m": "geometry/r_obj_eci_m"}[k]
            h[name][...] = v
    return p


@pytest.mark.parametrize("case", ["one_1e300", "all_1e300", "earth_centre"])
def test_filter_inputs_refused_at_the_boundary(case, tmp_path, capsys):
    """One 1e300 magnitude (the BPF raised OverflowError), all magnitudes 1e300 (UKF NaN
    quaternion), an object at the Earth's centre (inverted with exit 0): the HDF5 reader
    refuses them like the CSV reader, with exit 2 naming the dataset and row."""
    n = len(small_curve())
    if case == "one_1e300":
        mag = small_curve().mag.copy()
        mag[3] = 1e300
        p, frag = _h5_with(tmp_path, mag=mag), "magnitude out of range at row 3"
    elif case == "all_1e300":
        p, frag = _h5_with(tmp_path, mag=np.full(n, 1e300)), "magnitude out of range at row 0"
    else:
        p, frag = _h5_with(tmp_path, r_obj_eci_m=np.zeros((n, 3))), "object inside the Earth"
    for argv in (["invert", p, "-o", tmp_path / "o", "--method", "bpf", "--particles", "200",
                  "--workers", "1", "-q"], ["plot", p, "-o", tmp_path / "x.png"]):
        code, err = run_cli(argv, capsys)
        assert code == 2 and frag in err and str(p) in err, err
    with pytest.raises(InputError, match="out of range|inside the Earth"):
        replace(small_curve(), mag=np.full(n, 1e300) if case != "earth_centre"
                else small_curve().mag, r_obj_eci_m=np.zeros((n, 3)) if case == "earth_centre"
                else small_curve().r_obj_eci_m)


def _default_curve():
    from lightcurve.studies.scenario import parse_scenario
    from lightcurve.studies.simulate import simulate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(parse_scenario(DEFAULT, file="leo-ic1-fast-spin-controlled-1site.toml"))


def test_extreme_in_range_magnitudes_keep_the_filters_finite():
    """The largest magnitude the boundary lets through (39.9, i.e. ~30 mag off) as one outlier
    leaves every filter finite and ends where the clean run ends (the gate inflates or rejects
    it); a curve of nothing but such values keeps them finite and is flagged diverged."""
    from lightcurve.filters.invert import invert

    lc = _default_curve()
    one = lc.mag.copy()
    one[30] = 39.9
    for method in ("mekf", "ukf", "bpf"):
        clean = invert(lc, method, seed=0, particles=2000)
        est = invert(replace(lc, mag=one), method, seed=0, particles=2000)
        assert np.all(np.isfinite(est.q)) and np.all(np.isfinite(est.cov))
        assert est.diverged == clean.diverged
        d = np.linalg.norm(est.att_error_deg[-1]) - np.linalg.norm(clean.att_error_deg[-1])
        assert abs(d) < 1.0, (method, d)
        est = invert(replace(lc, mag=np.full(len(lc), 39.9)), method, seed=0, particles=2000)
        assert np.all(np.isfinite(est.q)) and est.diverged


@pytest.mark.parametrize("after_gap", [1, 2, 5])
def test_long_gap_is_not_a_silent_confident_answer(after_gap):
    """A 10⁸ s gap before the last epochs of the default curve: the MEKF ended 118-177° off
    with a 1-3° sigma and no flag. Now the estimate is flagged (attitude lost across the gap)
    unless its final error is inside its own 3σ."""
    from lightcurve.filters.invert import invert

    lc = _default_curve()
    t = lc.t.copy()
    t[len(lc) - after_gap:] += 1e8
    est = invert(replace(lc, t=t), "mekf", seed=0)
    inside = np.all(np.abs(est.att_error_deg[-1]) <= 3 * est.att_sigma_deg[-1])
    assert est.diverged or inside, (est.att_error_deg[-1], est.att_sigma_deg[-1])
    if not inside:
        assert "gap" in est.divergence_reason or "NIS" in est.divergence_reason


# ----------------------------------------------------------------------------------------
# smaller defects
# ----------------------------------------------------------------------------------------
def test_decayed_tle_error_is_one_short_line(tmp_path, capsys):
    """The decayed-TLE error listed one `None` per good epoch (hundreds); found while
    simulating a scenario, it named neither the scenario file nor the field."""
    from lightcurve.geometry.orbits import tle_positions

    def fix(line):  # TLE checksum: digits plus one per minus sign, modulo 10
        s = sum(int(c) if c.isdigit() else (c == "-") for c in line[:68])
        return line[:68] + str(s % 10)

    l1 = fix("1 25544U 98067A   20061.33750000  .99999999  00000-0  99999-0 0  9990")
    l2 = fix("2 25544  51.6443 209.2430 0005375  27.5532  66.2936 16.49000000214430")
    with pytest.raises(InputError) as ei:
        tle_positions(l1, l2, "2020-03-01T08:06:00Z", np.arange(0, 40 * 86400.0, 600.0))
    text = str(ei.value)
    assert "None" not in text and len(text) < 600 and "of 5760 requested time(s)" in text
    # the same TLE in a scenario: the line names the scenario file and its [orbit] lines
    orbit = DEFAULT[DEFAULT.index("[orbit]"):DEFAULT.index("[shape]")]
    p = _scenario(tmp_path, DEFAULT.replace(
        orbit, f'[orbit]\ntype = "tle"\nline1 = "{l1}"\nline2 = "{l2}"\n\n'))
    code, err = run_cli(["simulate", p, "-o", tmp_path / "o.h5"], capsys)
    line = one_line(err)
    assert code == 2 and f"{p}: field 'orbit.line1/line2': SGP4 failed" in line, err
    assert not (tmp_path / "o.h5").exists()


def test_unknown_brdf_imports_no_plugin(monkeypatch):
    """An unknown BRDF name (from a material file) used to load every installed plug-in."""
    import importlib.metadata as md

    import lightcurve.photometry.brdf as brdf_mod

    loaded = []

    class FakeEP:
        def __init__(self, name):
            self.name, self.value = name, f"evil_{name}:x"

        def load(self):
            loaded.append(self.name)
            raise ImportError("must not be imported")

    monkeypatch.setattr(md, "entry_points", lambda group=None: [FakeEP("a"), FakeEP("b")]
                        if group == "lightcurve.brdfs" else [])
    monkeypatch.setattr(brdf_mod, "_ENTRY_POINTS_LOADED", False)
    with pytest.raises(InputError) as ei:
        brdf_mod.get_brdf("no_such_brdf", file="m.toml", field="materials.x.brdf")
    assert loaded == [] and "a, " in str(ei.value) and "m.toml" in str(ei.value)


def test_warnings_are_one_line_and_numpy_chatter_hidden(capsys, monkeypatch):
    import lightcurve.cli as cli

    def cmd(args):
        warnings.warn("something the user should know\nsecond line", UserWarning)
        np.array([1.0]) / np.array([0.0])  # divide by zero: NumPy chatter
        with np.errstate(all="warn"):
            np.log(np.array([-1.0]))
        return 0

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    parser._subparsers._group_actions[0].choices["selfcheck"].set_defaults(func=cmd)
    assert cli.main(["selfcheck"]) == 0
    err = capsys.readouterr().err
    assert err.splitlines() == ["lightcurve: warning: something the user should know second line"]


def test_errors_name_the_file(tmp_path, capsys):
    """A batch input error and a fit-reflection model error used to omit the file."""
    p = tmp_path / "nolight.h5"
    small_curve().write(p)  # synthetic geometry: no lit facet faces the observer
    code, err = run_cli(["fit-reflection", p, "-o", tmp_path / "fr"], capsys)
    assert code == 2 and str(p) in one_line(err), err
    lc = small_curve()
    lc.attrs["shape"] = "no_such_shape"
    q = tmp_path / "noshape.h5"
    lc.write(q)
    code, err = run_cli(["invert", q, p, "-o", tmp_path / "inv", "--workers", "1", "-q"], capsys)
    assert code == 2
    bad = [ln for ln in err.splitlines() if "no_such_shape" in ln]
    assert bad and str(q) in bad[0], err


def test_site_file_fault_names_the_site_file(tmp_path, capsys):
    """A fault inside a site catalog file reached through a scenario's `[[sites]] name` (a
    latitude of 1000°, a FIFO in the `--sites` folder) is reported on the site file, its key
    and value — it used to be reported as `s.toml: field 'sites[0].name' ... (got 'socorro')`,
    naming neither the faulty file nor the faulty value."""
    import os

    scen = _scenario(tmp_path, DEFAULT)
    sites = tmp_path / "sites"
    sites.mkdir()
    text = (data_dir("observatories") / "socorro.toml").read_text()
    bad = tmp_path / "sites" / "socorro.toml"
    bad.write_text("\n".join("lat_deg = 1000.0" if ln.startswith("lat_deg") else ln
                             for ln in text.splitlines()) + "\n")
    assert "lat_deg = 1000.0" in bad.read_text()
    code, err = run_cli(["simulate", scen, "-o", tmp_path / "o.h5", "--sites", sites], capsys)
    line = one_line(err)
    assert code == 2 and str(bad) in line and "lat_deg" in line and "1000" in line, line
    assert "'socorro'" in line and str(scen) in line  # where it was asked for
    bad.unlink()
    os.mkfifo(tmp_path / "sites" / "pipe.toml")
    code, err = run_cli(["simulate", scen, "-o", tmp_path / "o.h5", "--sites", sites], capsys)
    line = one_line(err)
    assert code == 2 and str(tmp_path / "sites" / "pipe.toml") in line and "FIFO" in line, line
    assert not (tmp_path / "o.h5").exists()


def test_embedded_shape_inertia_too_large_names_the_dataset(tmp_path, capsys):
    """A received lightcurve whose stored shape has inertia 1e308: exit 2 naming
    `shape/inertia_kg_m2`, the value and the limit, as for a shape TOML (it used to end in
    "corrupted or unexpected HDF5 content: Eigenvalues did not converge")."""
    import h5py

    from lightcurve.photometry import load_shape

    lc = small_curve()
    lc.shape = load_shape("cube_1u")
    p = tmp_path / "heavy.h5"
    lc.write(p)
    with h5py.File(p, "r+") as h:
        h["shape/inertia_kg_m2"][...] = np.eye(3) * 1e308
    code, err = run_cli(["invert", p, "-o", tmp_path / "inv", "--workers", "1", "-q"], capsys)
    lines = [ln for ln in err.splitlines() if ln.startswith("lightcurve: error:")]
    assert code == 2 and len(lines) == 1, err
    line = lines[0]
    assert str(p) in line and "shape/inertia_kg_m2" in line, line
    assert "1e+308" in line and "1e+12" in line, line


def test_numpy_values_shown_as_plain_numbers(tmp_path, capsys):
    """`omega_deg_s = [1e308, ...]` is reported as `(got 1e+308)`, not `(got
    np.float64(1e+308))` (NumPy 2's repr of its scalars leaked into the one-line message)."""
    text = DEFAULT.replace("omega_deg_s = [2.0, 1.0, 3.6]", "omega_deg_s = [1e308, 1.0, 3.6]")
    assert text != DEFAULT
    p = _scenario(tmp_path, text)
    code, err = run_cli(["simulate", p, "-o", tmp_path / "o.h5"], capsys)
    line = one_line(err)
    assert code == 2 and "attitude.omega_deg_s" in line and "(got 1e+308)" in line, line
    assert str(InputError("x", value=np.float64(0.5))) == "x (got 0.5)"
    assert str(InputError("x", value=np.int64(3))) == "x (got 3)"


def test_dask_local_success_is_silent_on_stderr(tmp_path):
    """A successful `invert --dask-local 1 -q` (a real subprocess: the scheduler, nanny and
    worker log through `logging`, which capsys does not see) prints nothing on stderr — no
    Dask nanny or scheduler chatter."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    pytest.importorskip("distributed", reason="the 'distributed' extra is not installed")
    p = tmp_path / "a.h5"
    small_curve().write(p)
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "lightcurve", "invert", str(p), "-o",
                           str(tmp_path / "inv"), "--dask-local", "1", "-q"], env=env,
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "", proc.stderr
    assert (tmp_path / "inv" / "a.ukf.h5").is_file()
