"""Reference runs of the bootstrap particle filter, stored from an earlier implementation.

``python tests/filters/bpf_reference.py OUT.npz`` runs every case of :data:`CASES` and stores
the per-epoch posterior (q̂, ω̂, covariance, N_eff, flags, tempering stages, extra states).
``tests/filters/data/bpf_reference_main_ab055e3.npz`` was written by the implementation on
main at commit ab055e3 (before the particle kernels were rewritten); the test
``test_filters_bpf_reference.py`` checks that the current filter reproduces it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from filters_synth import make_curve  # noqa: E402


def _problem(case):
    from lightcurve.filters import build_problem

    c = case.get("curve", {})
    lc = make_curve(**c)
    if case.get("bias_mag"):
        lc.mag = lc.mag + case["bias_mag"]
    extra = {"reflection": "model3"} if case.get("attitude") == "truth" else {}
    return build_problem(lc, seed=case.get("problem_seed", 2),
                         sigma_theta_deg=case.get("sigma_theta_deg", 3.0),
                         acs_mode=case.get("acs_mode", "random_walk"),
                         attitude=case.get("attitude", "estimate"), **extra)


#: name → settings (curve: make_curve kwargs; kw: run_bpf keyword arguments)
CASES = {
    "ctrl_progressive": dict(sigma_theta_deg=10.0, kw=dict(particles=400, seed=3)),
    "ctrl_plain": dict(sigma_theta_deg=10.0, kw=dict(particles=400, seed=3, progressive=False)),
    "ctrl_separate_multinomial": dict(sigma_theta_deg=10.0,
                                      kw=dict(particles=400, seed=4, rejuvenation="separate",
                                              resampling="multinomial")),
    "ctrl_wide_60deg": dict(curve=dict(n=30), sigma_theta_deg=60.0,
                            kw=dict(particles=1000, seed=5)),
    "tumbling": dict(curve=dict(n=50, seed=9, dynamics="uncontrolled",
                                omega_deg_s=(2.0, -3.0, 4.0)),
                     kw=dict(particles=400, seed=3)),
    "jitter": dict(curve=dict(n=40, seed=21, acs_sigma_deg=0.3, acs_mode="jitter"),
                   acs_mode="jitter", kw=dict(particles=400, seed=5)),
    "bias_model1": dict(curve=dict(n=40, seed=3), bias_mag=0.15, bias="model1",
                        kw=dict(particles=300, seed=0)),
    "facets_combined": dict(curve=dict(n=30, seed=3), facets=True,
                            kw=dict(particles=300, seed=4)),
    "facets_truth_moves": dict(curve=dict(n=30, seed=3), facets=True, attitude="truth",
                               kw=dict(particles=300, seed=4, attitude="truth")),
    "numpy_ctrl_progressive": dict(sigma_theta_deg=10.0, backend="numpy",
                                   kw=dict(particles=400, seed=3)),
}


def run_case(name):
    """Run one case of :data:`CASES` → Estimate."""
    from lightcurve.filters import run_bpf, run_bpf_numpy
    from lightcurve.filters.facet_states import FacetParameterStates
    from lightcurve.filters.reflection import SiteBias

    case = CASES[name]
    p = _problem(case)
    kw = dict(case["kw"])
    if case.get("bias"):
        kw["bias"] = SiteBias.from_problem(case["bias"], p)
    if case.get("facets"):
        kw["facets"] = FacetParameterStates(p.model.shape, prior_frac=0.1)
    run = run_bpf_numpy if case.get("backend") == "numpy" else run_bpf
    return run(p, **kw)


def arrays(est):
    """The stored fields of one Estimate."""
    out = {"q": est.q, "omega": est.omega_rad_s, "cov": est.cov, "n_eff": est.n_eff,
           "flags": est.flags, "stages": np.asarray(est.meta.get("tempering_stages", []))}
    for k in ("bias", "bias_sigma", "refl_p", "refl_p_sigma"):
        v = getattr(est, k)
        if v is not None:
            out[k] = v
    return out


def main(path):
    store = {}
    for name in CASES:
        for k, v in arrays(run_case(name)).items():
            store[f"{name}/{k}"] = np.asarray(v)
    np.savez_compressed(path, **store)


if __name__ == "__main__":
    main(sys.argv[1])
