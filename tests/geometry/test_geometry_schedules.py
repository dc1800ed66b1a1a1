"""Schedules on a cadence grid; Bernard's two-site switching pattern."""

import numpy as np
import pytest

from lightcurve.errors import InputError
from lightcurve.geometry import schedules as sc


def test_bernard_switching_pattern():
    # Bernard (2021) ch. 9: site 2 at 0–100 s and 205–260 s, site 1 at 105–200 s and 300–400 s,
    # 5 s cadence → site 2: 21 + 12 = 33 epochs, site 1: 20 + 21 = 41 epochs
    t, s = sc.bernard_switching_schedule()
    assert np.all(np.diff(t) > 0)          # no overlap in this pattern: strictly increasing
    assert (s == 1).sum() == 33 and (s == 0).sum() == 41
    assert set(t[s == 1]) == set(np.r_[np.arange(0, 101, 5), np.arange(205, 261, 5)].astype(float))
    assert t[s == 0][0] == 105.0 and t[s == 0][-1] == 400.0
    assert 265.0 not in t and 295.0 not in t and 100.0 in t


def test_overlapping_windows_two_rows_and_default():
    t, s = sc.build_schedule(20.0, 5.0, [[(0, 10)], [(5, 20)]])
    assert list(zip(t, s)) == [(0, 0), (5, 0), (5, 1), (10, 0), (10, 1), (15, 1), (20, 1)]
    t, s = sc.build_schedule(1.0, 0.1)
    assert t.size == 11 and np.all(s == 0)
    assert abs(t[-1] - 1.0) < 1e-12        # integer-multiple grid: no accumulated rounding


def test_bad_windows_and_cadence():
    with pytest.raises(InputError):
        sc.build_schedule(100.0, 0.0)
    with pytest.raises(InputError, match="end before"):
        sc.build_schedule(100.0, 5.0, [[(50, 10)]])
    with pytest.raises(InputError, match="pair"):
        sc.build_schedule(100.0, 5.0, [[(50,)]])


def test_windows_from_flags():
    t = np.arange(10.0)
    f = np.array([0, 1, 1, 0, 0, 1, 1, 1, 0, 1], bool)
    assert sc.windows_from_flags(t, f) == [(1.0, 2.0), (5.0, 7.0), (9.0, 9.0)]
    assert sc.windows_from_flags(t, np.ones(10, bool)) == [(0.0, 9.0)]
