"""Fuzz: CSS inputs — albedo maps (load_albedo_map), sensor-configuration TOML
(load_configuration) and CSS study TOML (load_css_study).

Property: damaged or hostile files give an InputError naming the file, or a valid
object (albedo values in [0, 1], unit sensor normals).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardening_util import (damaged_bytes, dumps_toml, fuzz_settings, mutated_docs, new_tmp_dir,
                            only_input_error)
from lightcurve import InputError
from lightcurve._paths import data_dir
from lightcurve.css.albedo import load_albedo_map


def _write(data: bytes, name: str) -> Path:
    p = new_tmp_dir() / name
    p.write_bytes(data)
    return p


def _ceres(nlat=18, nlon=36, value=0.3) -> bytes:
    rows = [",".join(f"{value:.3f}" for _ in range(nlon)) for _ in range(nlat)]
    return ("\n".join(rows) + "\n").encode()


GOOD_CERES = _ceres()
GOOD_TOMS = ("\n".join(" ".join("30.0" for _ in range(18)) for _ in range(36)) + "\n").encode()


@fuzz_settings(100)
@given(st.one_of(st.binary(max_size=600), damaged_bytes(GOOD_CERES), damaged_bytes(GOOD_TOMS)),
       st.sampled_from(["map.csv", "map.dat"]))
def test_albedo_map_random_and_damaged(data, name):
    p = _write(data, name)
    out = only_input_error("albedo map (load_albedo_map)", load_albedo_map, p, file=p)
    if not isinstance(out, InputError):
        v = np.asarray(out.values)
        assert np.all(np.isfinite(v)) and v.min() >= 0 and v.max() <= 1


@fuzz_settings(60)
@given(st.integers(0, 17), st.integers(0, 35),
       st.sampled_from(["nan", "inf", "-inf", "-0.1", "1.5", "1e999", "x", "", "0x1", "٣"]))
def test_albedo_map_hostile_cells(r, c, text):
    rows = [["0.300"] * 36 for _ in range(18)]
    rows[r][c] = text
    p = _write(("\n".join(",".join(x) for x in rows) + "\n").encode(), "cell.csv")
    out = only_input_error("albedo map (load_albedo_map)", load_albedo_map, p, file=p)
    if text in ("nan", "inf", "-inf", "-0.1", "1.5", "1e999"):
        assert isinstance(out, InputError)


@pytest.mark.parametrize("shape", [(17, 36), (18, 35), (1, 1), (180, 361)])
def test_albedo_map_wrong_shape(shape):
    p = _write(_ceres(*shape), "shape.csv")
    with pytest.raises(InputError, match="wrong shape"):
        load_albedo_map(p)


def test_albedo_map_huge_file_refused_from_size():
    p = _write(b"", "huge.csv")
    with open(p, "r+b") as fh:
        fh.truncate(2 * 1024**3)  # sparse 2 GiB: must not be read
    with pytest.raises(InputError, match=r"huge\.csv.*too large"):
        load_albedo_map(p)


def test_shared_ceres_maps_load():
    """The real CERES 2018 maps are accepted (regression guard for the checks above)."""
    from lightcurve._paths import shared_data_dir

    d = shared_data_dir()
    if d is None:
        pytest.skip("../shared/data not present")
    m = load_albedo_map(d / "earth_albedo" / "Earth_ALB_2018_CERES_All_10x10.csv")
    assert 0.2 < float(np.mean(m.values)) < 0.5


# ----------------------------------------------------------------------------------------
# sensor configurations
# ----------------------------------------------------------------------------------------
GOOD_CONF = {"name": "fuzz", "fov_half_angle_deg": 70.0, "noise_sigma": 0.01,
             "sensor": [{"normal": [1.0, 0.0, 0.0]}, {"azimuth_deg": 90.0, "elevation_deg": 10.0},
                        {"normal": [0.0, 0.0, 1.0], "scale": 1.1, "fov_half_angle_deg": 60.0}]}


@fuzz_settings(100)
@given(st.one_of(mutated_docs(GOOD_CONF).map(lambda d: dumps_toml(d).encode()),
                 damaged_bytes(dumps_toml(GOOD_CONF).encode())))
def test_css_configuration_toml(data):
    from lightcurve.css.configurations import load_configuration

    p = _write(data, "conf.toml")
    out = only_input_error("CSS configuration TOML", load_configuration, p, file=p)
    if not isinstance(out, InputError):
        n = np.asarray(out.normals)
        assert np.all(np.isfinite(n)) and np.allclose(np.linalg.norm(n, axis=1), 1.0)


# ----------------------------------------------------------------------------------------
# CSS study TOML
# ----------------------------------------------------------------------------------------
def _study_base():
    d = data_dir("pipelines") / "css"
    files = sorted(d.glob("*.toml"))
    return tomllib.loads(files[0].read_text()) if files else None


STUDY = _study_base()


@pytest.mark.skipif(STUDY is None, reason="no pipelines/css/*.toml study file bundled")
@fuzz_settings(100)
@given(st.one_of(mutated_docs(STUDY or {"a": 1}).map(lambda d: dumps_toml(d).encode()),
                 damaged_bytes(dumps_toml(STUDY or {"a": 1}).encode())))
def test_css_study_toml(data):
    from lightcurve.css.study import load_css_study

    p = _write(data, "study.toml")
    only_input_error("CSS study TOML (load_css_study)", load_css_study, p, file=p)
