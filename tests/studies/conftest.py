"""Fixtures of the study tests: a short scenario (13 epochs) and small study files."""

from __future__ import annotations

import pytest

# the LEO IC1 fast-spin case of Bernard (2021) §9.3, shortened to 60 s so a run takes ~0.05 s
TINY_SCENARIO = """
[scenario]
name = "tiny-{dynamics}"
epoch_utc = "2020-03-01T08:08:40Z"
duration_s = 60.0
cadence_s = 5.0
seed = 1
[orbit]
type = "keplerian"
a_km = 6871.14
e = 0.01
i_deg = 83.0
raan_deg = 0.0
argp_deg = 0.0
nu_deg = 126.264
gravity = "J4"
[shape]
name = "cube_1u"
[attitude]
dynamics = "{dynamics}"
euler321_deg = [-42.4122, 59.1601, 48.9897]
omega_deg_s = [2.0, 1.0, 3.6]
{extra}
[[sites]]
name = "socorro"
windows_s = [[0.0, 60.0]]
[measurement]
r_percent = 1.0
ignore_eclipse = true
"""

_EXTRA = {"controlled": "acs_sigma_deg = 0.1", "uncontrolled": 'torques = ["gravity_gradient"]'}


def write_study(folder, *, filters=("ukf", "mekf"), runs=3, seed=7, sigma_theta=(3.0,),
                dynamics=("controlled",), reflection=None, name="small"):
    """Write tiny scenarios and a study TOML into ``folder``; return the study path."""
    for dyn in ("controlled", "uncontrolled"):
        (folder / f"tiny-{dyn}-1site.toml").write_text(
            TINY_SCENARIO.format(dynamics=dyn, extra=_EXTRA[dyn]), encoding="utf-8")
    q = lambda xs: "[" + ", ".join(f'"{x}"' if isinstance(x, str) else repr(x) for x in xs) + "]"
    text = f"""
[study]
name = "{name}"
seed = {seed}
runs = {runs}
scenario = "tiny-{{dynamics}}-{{sites}}site.toml"
[grid]
filter = {q(filters)}
dynamics = {q(dynamics)}
sites = [1]
sigma_theta_deg = {q(sigma_theta)}
sigma_omega_deg_s = [0.02]
r_percent = [1.0]
"""
    if reflection is not None:
        text += f"reflection = {q(reflection)}\n"
    path = folder / "study.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture
def study_file(tmp_path):
    """A 2-cell (UKF, MEKF) × 3-run study on the tiny controlled scenario."""
    return write_study(tmp_path)


@pytest.fixture
def make_study():
    """The :func:`write_study` helper (tests call it with their own grid)."""
    return write_study
