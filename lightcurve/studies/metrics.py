"""Monte Carlo metrics of filter runs: final errors, 3σ consistency, traffic-light colours.

Per run (from an :class:`~lightcurve.filters.Estimate` with truth): the final RSS attitude error
``|δθ_N|`` (deg; δθ the rotation vector of ``q_true ⊗ q̂⁻¹``, body axes, Bernard eq. 9.4–9.6),
the final RSS rate error ``|ω_true − ω̂|`` (deg/s) and, for each of the six components
``[δθ_x, δθ_y, δθ_z, δω_x, δω_y, δω_z]``, whether the final error lies outside the filter's own
3σ bound (``|e_i| > 3 σ_i``; a non-finite error or bound counts as outside).

Per cell: the six counts of runs outside 3σ and the colour of Bernard (2021) fig. 9.4
(§9.4.1, defined for 100 runs): red when more than 10 runs are outside for any component; yellow
when 6–9 runs are outside for some component, or two or more components have exactly 5; green
otherwise. (Exactly 10 runs outside — which the thesis's rule does not name — is yellow here:
more than 5 and not more than 10.)

Fewer (or more) runs: the thresholds scale with the run count n — each count c is read as the
count per 100 runs, ``c·100/n``, and the 100-run rule applied to that (red above 10, yellow
above 5 or two components at exactly 5). With 5 runs one run outside is already 20 per 100
(red), with 10 runs one run is yellow and two are red. A table from fewer than 100 runs per
cell is *indicative* (:data:`FULL_RUNS`).

Monte Carlo spread of a colour: a cell's colour is itself a random outcome of its runs.
:func:`color_probability` gives, from the runs' six outside-3σ flags, the probability of each
colour in an *independent* Monte Carlo of ``n`` runs of the same filter on the same cell: the
posterior predictive of the Bayesian bootstrap (Rubin 1981, Ann. Statist. 9, 130–134) — run
weights w ~ Dirichlet(1, …, 1) over the observed runs, then ``n`` new runs drawn from them
(multinomial), whose six counts are coloured by :func:`traffic_light`. For one component
with k of R runs outside this is the beta-binomial BB(n, k, R − k). Outcomes that no observed
run shows (a run outside in a component none was outside in) get probability zero.
"""

from __future__ import annotations

import numpy as np

__all__ = ["run_metrics", "outside_3sigma", "traffic_light", "traffic_lights", "color_probability",
           "cell_summary", "rss_envelope", "COLORS", "FULL_RUNS", "COLOR_DRAWS"]

COLORS = ("green", "yellow", "red")
#: the run count the thesis's traffic-light rule is defined for (§9.3.1: 100 runs per cell)
FULL_RUNS = 100
#: draws of :func:`color_probability` (Monte Carlo standard error of a probability ≤ 0.5/√4000
#: = 0.008)
COLOR_DRAWS = 4000


def outside_3sigma(att_error_deg, att_sigma_deg, omega_error_rad_s, omega_sigma_rad_s) -> np.ndarray:
    """Six booleans: final error component outside its 3σ bound (NaN → outside).

    Inputs are the final-epoch vectors (3,) each: attitude error and 1σ in deg (body axes),
    rate error and 1σ in rad/s (body axes).
    """
    e = np.concatenate([np.asarray(att_error_deg, float).reshape(3),
                        np.asarray(omega_error_rad_s, float).reshape(3)])
    s = np.concatenate([np.asarray(att_sigma_deg, float).reshape(3),
                        np.asarray(omega_sigma_rad_s, float).reshape(3)])
    inside = np.isfinite(e) & np.isfinite(s) & (np.abs(e) <= 3.0 * s)
    return ~inside


def run_metrics(estimate) -> dict:
    """Final-epoch metrics of one run (module docstring); needs ``estimate.att_error_deg``.

    Returns a dict of plain floats/lists: ``rss_att_deg``, ``rss_omega_deg_s``,
    ``outside`` (six 0/1), ``final_att_error_deg`` (3), ``final_omega_error_deg_s`` (3),
    ``final_att_sigma_deg`` (3), ``final_omega_sigma_deg_s`` (3), ``diverged``, ``runtime_s``;
    with per-site reflection-bias states also ``final_bias_mag`` and ``final_bias_sigma_mag``
    (S each, mag).
    """
    if estimate.att_error_deg is None:
        raise ValueError("run_metrics needs an estimate with truth (att_error_deg)")
    ea = np.asarray(estimate.att_error_deg[-1], float)
    ew = np.asarray(estimate.omega_error_rad_s[-1], float)
    sa = np.asarray(estimate.att_sigma_deg[-1], float)
    sw = np.asarray(estimate.omega_sigma_rad_s[-1], float)
    out = outside_3sigma(ea, sa, ew, sw)
    return {
        "rss_att_deg": float(np.linalg.norm(ea)),
        "rss_omega_deg_s": float(np.degrees(np.linalg.norm(ew))),
        "outside": [int(x) for x in out],
        "final_att_error_deg": [float(x) for x in ea],
        "final_omega_error_deg_s": [float(x) for x in np.degrees(ew)],
        "final_att_sigma_deg": [float(x) for x in sa],
        "final_omega_sigma_deg_s": [float(x) for x in np.degrees(sw)],
        "diverged": bool(estimate.diverged),
        "runtime_s": float(estimate.runtime_s),
        **_reflection_metrics(estimate),
    }


def _reflection_metrics(estimate) -> dict:
    """Final per-site reflection biases and 1σ (mag; Models 1–2 and random walk), if any."""
    b = getattr(estimate, "bias", None)
    bs = getattr(estimate, "bias_sigma", None)
    if b is None or bs is None:
        return {}
    return {"final_bias_mag": [float(x) for x in np.asarray(b)[-1]],
            "final_bias_sigma_mag": [float(x) for x in np.asarray(bs)[-1]]}


def traffic_lights(outside_counts, n_runs: int = FULL_RUNS) -> np.ndarray:
    """Colour indices into :data:`COLORS` (0 green, 1 yellow, 2 red) of many cells at once.

    ``outside_counts``: (..., 6) counts of runs outside 3σ out of ``n_runs`` each; the rule of
    :func:`traffic_light` (module docstring) on every row. Returns an int array of shape (...).
    """
    c = np.asarray(outside_counts)
    if c.shape[-1:] != (6,):
        raise ValueError(f"outside_counts must have 6 components in the last axis, got {c.shape}")
    c = c.astype(np.int64)
    n = int(n_runs)
    if n < 1:
        return np.where(np.any(c != 0, axis=-1), 2, 0)
    p100 = c * FULL_RUNS     # compare c·100/n with the thresholds in integers: c·100 vs t·n
    red = np.any(p100 > 10 * n, axis=-1)
    yellow = np.any(p100 > 5 * n, axis=-1) | (np.sum(p100 == 5 * n, axis=-1) >= 2)
    return np.where(red, 2, np.where(yellow, 1, 0))


def traffic_light(outside_counts, n_runs: int = FULL_RUNS) -> str:
    """Colour of Bernard fig. 9.4 from the six counts of runs outside 3σ out of ``n_runs``.

    With the counts per 100 runs ``p = c·100/n_runs`` (module docstring): ``"red"`` if any
    p > 10; ``"yellow"`` if any p > 5 or at least two p equal 5; ``"green"`` otherwise. For
    ``n_runs = 100`` this is the thesis's rule on the raw counts.
    """
    c = np.asarray(outside_counts, int).reshape(6)
    return COLORS[int(traffic_lights(c, n_runs))]


def color_probability(outside, n_runs: int = FULL_RUNS, *, draws: int = COLOR_DRAWS,
                      seed: int = 0) -> dict:
    """Probability of each colour in an independent ``n_runs``-run Monte Carlo of a cell.

    ``outside``: (R, 6) 0/1 flags of the cell's R finished runs (:func:`run_metrics`
    ``outside``). Bayesian-bootstrap posterior predictive (module docstring) with ``draws``
    draws from a generator seeded with ``seed`` (the result depends only on the flags, the
    draw count and the seed). Returns ``{"green": p, "yellow": p, "red": p}`` (summing to 1),
    or an empty dict without runs.
    """
    f = np.asarray(outside, dtype=np.int64)
    if f.ndim != 2 or f.shape[1] != 6:
        raise ValueError(f"outside must be (runs, 6) flags, got shape {f.shape}")
    if f.shape[0] == 0:
        return {}
    n, total = int(n_runs), int(draws)
    rng = np.random.default_rng(seed)
    hist = np.zeros(len(COLORS), np.int64)
    block = max(1, 4_000_000 // f.shape[0])          # bounded memory for studies of many runs
    for start in range(0, total, block):
        m = min(block, total - start)
        w = rng.dirichlet(np.ones(f.shape[0]), size=m)   # (m, R) run weights
        picks = rng.multinomial(n, w)                     # (m, R) new runs drawn per old run
        hist += np.bincount(traffic_lights(picks @ f, n), minlength=len(COLORS))
    return {name: float(k) / total for name, k in zip(COLORS, hist)}


def _pct(x, q):
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.percentile(x, q)) if x.size else float("nan")


def cell_summary(cell: dict, runs: list, failures: int) -> dict:
    """The summary.json entry of one cell (schema in docs/formats.md, "Studies").

    ``runs`` holds :func:`run_metrics` dicts of the runs that finished; ``failures`` counts the
    runs that raised. ``outside_3sigma`` counts finished runs only.
    """
    n = len(runs)
    counts = np.zeros(6, int)
    for r in runs:
        counts += np.asarray(r["outside"], int)
    rss = [r["rss_att_deg"] for r in runs]
    rssw = [r["rss_omega_deg_s"] for r in runs]
    rt = [r["runtime_s"] for r in runs]
    flags = np.asarray([r["outside"] for r in runs], int).reshape(n, 6)
    out = dict(cell)
    out.update({
        "runs": n,
        "outside_3sigma": [int(x) for x in counts],
        "color": traffic_light(counts, n),
        # the colour's Monte Carlo spread: P(colour) in an independent Monte Carlo of the
        # thesis's size (FULL_RUNS runs; color_probability)
        "color_probability": color_probability(flags, FULL_RUNS),
        "rss_att_deg_median": _pct(rss, 50),
        "rss_att_deg_p95": _pct(rss, 95),
        # share of finished runs ending below 5° RSS attitude error ("converged"; the
        # threshold of the BPF acceptance runs, used for the thesis's robustness claims)
        "below_5deg": (float(np.mean(np.asarray(rss, float) < 5.0)) if n else float("nan")),
        "rss_omega_deg_s_median": _pct(rssw, 50),
        "rss_omega_deg_s_p95": _pct(rssw, 95),
        "diverged": int(sum(bool(r["diverged"]) for r in runs)),
        "runtime_s_median": _pct(rt, 50),
        "failures": int(failures),
    })
    return out


def rss_envelope(t_list, rss_list, n_grid: int = 200):
    """Percentile envelope of RSS-error-versus-time curves of several runs.

    Each run's curve (``t`` s, ``rss``) is interpolated linearly onto a common grid spanning the
    shortest run's times. Returns ``(t_grid, p50, p95, p5)`` arrays; empty arrays for no runs.
    """
    pairs = [(np.asarray(t, float), np.asarray(r, float)) for t, r in zip(t_list, rss_list)
             if len(t) > 0]
    if not pairs:
        e = np.array([])
        return e, e, e, e
    t0 = max(p[0][0] for p in pairs)
    t1 = min(p[0][-1] for p in pairs)
    if t1 <= t0:
        t1 = t0
    grid = np.linspace(t0, t1, n_grid)
    Y = np.array([np.interp(grid, t, r) for t, r in pairs])
    with np.errstate(all="ignore"):
        return (grid, np.nanpercentile(Y, 50, axis=0), np.nanpercentile(Y, 95, axis=0),
                np.nanpercentile(Y, 5, axis=0))
