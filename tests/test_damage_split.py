"""DamageSplit: committed damage by load source and the band on the estimated part, by hand."""

from __future__ import annotations

import contextlib
import math

import numpy as np
import pytest

from models._jit import uncompiled
from monitor.damage_split import ASSUMED_ERROR, MIN_CAL_TICKS, DamageSplit

NAN = math.nan


def test_attribution_and_the_assumed_band_by_hand():
    s = DamageSplit({"c": 4.0})
    # tick 1: damage 0 -> 1.0, 3 of its 4 load samples measured; tick 2: 1.0 -> 3.0, all
    # estimated (no measured mean: nothing to calibrate on)
    s.ticks({"c": [1.0, 3.0]}, [(3, 4, 1000.0, 1100.0), (0, 4, NAN, 900.0)])
    f = s.figures("c", 3.5)  # 0.5 committed after the last evaluated tick
    assert f["measured"] == 0.75 and f["estimated"] == 2.25 and f["unattributed"] == 0.5
    # one calibration tick is too few: the assumed 30 %, band 2.25 x 0.7^4 .. 2.25 x 1.3^4
    assert f["estimate_error_from"] == "assumed" and f["calibration_ticks"] == 1
    assert f["estimate_relative_error"] == ASSUMED_ERROR == 0.30
    assert f["estimated_low"] == pytest.approx(2.25 * 0.2401, rel=1e-12)
    assert f["estimated_high"] == pytest.approx(2.25 * 2.8561, rel=1e-12)


def test_the_band_is_calibrated_on_the_measured_estimated_residual_by_hand():
    """30 ticks where both sources exist: one 10 % high, 29 20 % low, and one below the
    100 N floor (left out): u = sqrt((0.1^2 + 29 x 0.2^2) / 30) = sqrt(0.039)."""
    rows = [(4, 4, 1000.0, 1100.0)] + [(4, 4, 1000.0, 800.0)] * 29 + [(4, 4, 50.0, 500.0)]
    one = DamageSplit({"c": 3.0})
    one.ticks({"c": [0.0] * 31}, rows)
    # any split of the ticks into slabs gives the same figures
    two = DamageSplit({"c": 3.0})
    two.ticks({"c": [0.0] * 10}, rows[:10])
    two = DamageSplit({"c": 3.0}, two.state())
    two.ticks({"c": [0.0] * 21}, rows[10:])
    assert two.state() == one.state()  # to the last bit
    for s in (one, two):
        u, how = s.relative_error()
        assert how == "residual" and s.cal_n == MIN_CAL_TICKS == 30
        assert u == pytest.approx(math.sqrt(0.039), rel=1e-12)  # 0.19748
    # the band of 1.0 estimated damage with the S-N slope 3: (1 -+ u)^3
    three = DamageSplit({"c": 3.0}, one.state())
    three.ticks({"c": [1.0]}, [(0, 4, NAN, 500.0)])
    f = three.figures("c", 1.0)
    assert f["estimated"] == 1.0
    assert f["estimated_low"] == pytest.approx((1 - math.sqrt(0.039)) ** 3, rel=1e-12)  # 0.5167
    assert f["estimated_high"] == pytest.approx((1 + math.sqrt(0.039)) ** 3, rel=1e-12)  # 1.7170


@pytest.mark.parametrize("plain", [False, True])
def test_sums_run_left_to_right_so_any_slab_split_gives_the_same_bits(plain):
    """The compiled pass (and the same as plain Python) against the loop it stands for, with
    resets (a committed damage that drops) and ticks without samples."""
    with uncompiled() if plain else contextlib.nullcontext():
        _sums_left_to_right()


def _sums_left_to_right():
    rng = np.random.default_rng(7)
    committed = np.cumsum(rng.random(500) * 10.0 ** rng.integers(-12, 0, 500)).tolist()
    committed[300] = committed[299] / 2  # a reset: no negative damage is attributed
    rows = [(int(k), 4, float(m), float(e)) for k, m, e in
            zip(rng.integers(0, 5, 500), rng.uniform(50, 5000, 500), rng.uniform(0, 6000, 500))]
    rows[10] = (0, 0, NAN, NAN)  # a tick without samples
    rows[11] = (0, 3, NAN, 700.0)
    one = DamageSplit({"c": 4.5})
    one.ticks({"c": committed}, rows)
    measured = estimated = cal = 0.0
    last = 0.0
    for c, (k, n, m, e) in zip(committed, rows):  # the loop the sums stand for
        frac = k / n if n else 0.0
        measured += max(c - last, 0.0) * frac
        estimated += max(c - last, 0.0) * (1.0 - frac)
        if m >= 100.0:
            cal += ((e - m) / m) ** 2
        last = c
    assert (one.parts["c"]["measured"], one.parts["c"]["estimated"], one.cal_sum_sq) == (
        measured, estimated, cal)
    for cuts in ((1, 2, 499), (250,), tuple(range(7, 500, 7))):
        s = DamageSplit({"c": 4.5})
        for a, b in zip((0, *cuts), (*cuts, 500)):
            s = DamageSplit({"c": 4.5}, s.state())
            s.ticks({"c": committed[a:b]}, rows[a:b])
        assert s.state() == one.state()
