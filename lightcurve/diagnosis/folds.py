"""Blocked cross-validation folds over whatever a recording has.

A *group* is a unit of data that must be held out as a whole because its measurements share
errors a model could learn from one part and "predict" in another: an object (one satellite),
a night, a camera, a pass (a run of measurements without gaps), or a contiguous block of time.
Groups are sorted by their first time stamp and dealt round-robin into ``k`` folds (group j
goes to fold j mod k), so every fold spans the whole recording — all seasons, the whole pass —
while no group is ever split between training and held-out data. Contiguous time blocks are
cut ``BLOCKS_PER_FOLD`` per fold: a localised effect (one shadow crossing, a few flashes) then
has held-out *and* training data in every fold, as it must to be predicted at all, and each
held-out block is still a contiguous stretch whose neighbours' correlated errors do not
reach into it beyond its edges. Every measurement is held out exactly once.

Which grouping (:func:`make_folds` with ``by="auto"``): objects when the recording has two or
more, else nights, else passes, else contiguous time blocks. Cameras (and sites) are only
used when asked for: leaving a camera out makes its own calibration (a per-camera zero point)
unpredictable by construction. Fewer than two groups, or fewer than ``min_per_fold``
measurements in a fold, means no cross-validation is possible; the reason is returned and
reported (screen and ``diagnosis.json``).

Passes: measurements of one object (from any site) separated by gaps longer than
``max(PASS_GAP_S, 10 × the median spacing)`` start a new pass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Folds", "make_folds", "available_groupings", "GROUPINGS", "PASS_GAP_S",
           "DEFAULT_FOLDS"]

#: gap (s) that always starts a new pass
PASS_GAP_S = 300.0
#: default number of folds
DEFAULT_FOLDS = 5
#: contiguous time blocks per fold (``blocks`` grouping)
BLOCKS_PER_FOLD = 10
#: grouping names accepted by :func:`make_folds` (besides "auto")
GROUPINGS = ("objects", "nights", "passes", "cameras", "sites", "blocks")
_METHOD = {"objects": "leave-objects-out", "nights": "leave-nights-out",
           "passes": "leave-passes-out", "cameras": "leave-cameras-out",
           "sites": "leave-sites-out", "blocks": "leave-time-blocks-out"}
_UNIT = {"objects": "object", "nights": "night", "passes": "pass", "cameras": "camera",
         "sites": "site", "blocks": "time block"}
_PLURAL = {"pass": "passes"}


@dataclass
class Folds:
    """Cross-validation folds of a problem's measurements.

    ``grouping`` (one of :data:`GROUPINGS`), ``method`` (e.g. "leave-nights-out"),
    ``labels`` (M,) fold index 0…k−1 of every measurement, ``n_groups`` (nights, objects …
    in the data), ``n_folds`` k.
    """

    grouping: str
    method: str
    labels: np.ndarray
    n_groups: int
    n_folds: int

    def masks(self):
        """Boolean held-out masks (M,), one per fold."""
        return [self.labels == j for j in range(self.n_folds)]

    def describe(self) -> str:
        unit = _UNIT[self.grouping]
        units = _PLURAL.get(unit, unit + "s")
        return (f"{self.method}: {self.n_groups} {unit if self.n_groups == 1 else units} "
                f"dealt in time order into {self.n_folds} folds")

    def as_dict(self) -> dict:
        return {"grouping": self.grouping, "method": self.method, "n_groups": int(self.n_groups),
                "n_folds": int(self.n_folds),
                "fold_sizes": [int(np.sum(self.labels == j)) for j in range(self.n_folds)]}


def _passes(t, key, min_gap=PASS_GAP_S):
    """Pass index (M,) per measurement: runs of ``key`` (object/site) without long gaps."""
    t = np.asarray(t, float)
    out = np.zeros(t.size, np.int64)
    nxt = 0
    for k in np.unique(key):
        m = np.flatnonzero(key == k)
        order = m[np.argsort(t[m], kind="stable")]
        tu = np.unique(t[order])
        gap = max(min_gap, 10.0 * float(np.median(np.diff(tu)))) if tu.size > 2 else min_gap
        cuts = np.r_[0, np.flatnonzero(np.diff(t[order]) > gap) + 1, order.size]
        for a, b in zip(cuts[:-1], cuts[1:]):
            out[order[a:b]] = nxt
            nxt += 1
    return out


def _blocks(t, n_blocks):
    """Contiguous time blocks (M,) with nearly equal counts (ties in time stay together)."""
    t = np.asarray(t, float)
    tu, inv = np.unique(t, return_inverse=True)
    counts = np.bincount(inv)
    cum = np.cumsum(counts) / t.size
    blk = np.minimum((cum - 0.5 * counts / t.size) * n_blocks, n_blocks - 1e-9).astype(np.int64)
    return blk[inv]


def available_groupings(problem) -> dict:
    """Grouping name → (M,) group id per measurement, for every grouping with ≥ 2 groups.

    ``blocks`` is always present when there are ≥ 2 distinct times (it is built for the
    requested number of folds by :func:`make_folds`).
    """
    ei = problem.epoch_index
    out = {}
    for name, arr in (("objects", problem.object), ("nights", problem.night),
                      ("cameras", problem.camera)):
        if arr is not None:
            g = np.asarray(arr)[ei]
            if np.unique(g).size >= 2:
                out[name] = g
    if problem.kind == "magnitude" and np.unique(problem.site).size >= 2:
        out["sites"] = np.asarray(problem.site)
    # a pass belongs to one object; sites observing it at the same time share the pass
    key = np.asarray(problem.object)[ei] if problem.object is not None else np.zeros(problem.n, np.int64)
    p = _passes(problem.t, key)
    if np.unique(p).size >= 2:
        out["passes"] = p
    if np.unique(problem.t).size >= 2:
        out["blocks"] = None
    return out


def _deal(groups, t, k):
    """Assign groups round-robin, in order of their first time, to k folds."""
    gids, inv = np.unique(groups, return_inverse=True)
    first = np.full(gids.size, np.inf)
    np.minimum.at(first, inv, np.asarray(t, float))
    order = np.argsort(first, kind="stable")
    fold = np.empty(gids.size, np.int64)
    fold[order] = np.arange(gids.size) % k
    # renumber so that every label 0..k'-1 is used
    used, lab = np.unique(fold[inv], return_inverse=True)
    return lab, used.size


def make_folds(problem, by: str = "auto", k: int = DEFAULT_FOLDS, min_per_fold: int = 5):
    """Cross-validation folds of ``problem`` (module docstring).

    Returns ``(folds, reason)``: a :class:`Folds` and ``None``, or ``None`` and a one-line
    reason why no cross-validation is possible with ``by`` on these data.
    """
    if by != "auto" and by not in GROUPINGS:
        raise ValueError(f"unknown grouping {by!r}; allowed: auto, {', '.join(GROUPINGS)}")
    k = int(k)
    if k < 2:
        return None, "fewer than 2 folds requested"
    avail = available_groupings(problem)
    if by == "auto":
        order = [g for g in ("objects", "nights", "passes", "blocks") if g in avail]
        if not order:
            return None, ("no cross-validation possible: the recording has a single time stamp "
                          "(no objects, nights, passes or time blocks to hold out)")
        by = order[0]
    if by not in avail:
        what = {"objects": "fewer than 2 objects", "nights": "fewer than 2 nights",
                "cameras": "fewer than 2 cameras", "sites": "fewer than 2 sites",
                "passes": "a single pass", "blocks": "a single time stamp"}[by]
        return None, f"no {_METHOD[by]} cross-validation possible: the recording has {what}"
    if by == "blocks":
        nb = BLOCKS_PER_FOLD * k
        while nb > k and problem.n / nb < max(min_per_fold, 3):
            nb -= k
        groups = _blocks(problem.t, nb)
    else:
        groups = avail[by]
    n_groups = int(np.unique(groups).size)
    if problem.kind == "css":
        # CSS measurements are epoch-major: hold out whole epochs
        g_ep = np.zeros(int(problem.epoch_index.max()) + 1, np.int64)
        g_ep[problem.epoch_index] = groups
        groups = g_ep[problem.epoch_index]
    labels, kk = _deal(groups, problem.t, min(k, n_groups))
    if kk < 2:
        return None, f"no {_METHOD[by]} cross-validation possible: fewer than 2 folds"
    sizes = np.bincount(labels, minlength=kk)
    if sizes.min() < min_per_fold:
        return None, (f"no {_METHOD[by]} cross-validation possible: a fold would hold "
                      f"{int(sizes.min())} measurements (< {min_per_fold})")
    return Folds(by, _METHOD[by], labels, n_groups, kk), None
