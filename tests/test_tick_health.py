"""monitor.tick_health: a stream's health at tick ends in one compiled pass is numpy's
``searchsorted(side="right")`` and its differences to the element, compiled and as plain
Python, for sorted and unsorted samples and keys (numpy's binary search carries its bounds
from key to key: on unsorted input only the same search gives the same answer)."""

from __future__ import annotations

import numpy as np
import pytest

from models._jit import uncompiled
from monitor.tick_health import tick_health


def _numpy(rx, rej, acc, ends):
    cut = np.searchsorted(rx, ends, side="right")
    rcut = np.searchsorted(rej, ends, side="right")
    k = np.searchsorted(acc, ends, side="right")
    last = np.where(k > 0, acc[np.maximum(k - 1, 0)] if acc.shape[0] else 0, 0)
    return np.diff(cut, prepend=0), np.diff(rcut, prepend=0), k, last


@pytest.mark.parametrize("plain", [False, True])
def test_tick_health_is_numpys_search(plain):
    rng = np.random.default_rng(22)
    for trial in range(600):
        n = int(rng.integers(0, 50))
        rx = rng.integers(0, 100, n)
        if trial % 3:
            rx = np.sort(rx)  # a slab's times; unsorted: time_backwards samples received
        rej = rx[rng.random(n) < 0.2]
        acc = rx[rng.random(n) < 0.7]
        ends = rng.integers(-5, 110, int(rng.integers(1, 12)))
        if trial % 5:
            ends = np.sort(ends)
        args = [a.astype(np.int64) for a in (rx, rej, acc, ends)]
        if plain:
            with uncompiled():
                got = tick_health(*args)
        else:
            got = tick_health(*args)
        for a, b in zip(got, _numpy(*args)):
            assert a.dtype == np.int64
            np.testing.assert_array_equal(a, b)


def test_tick_health_by_hand():
    # ticks ending at 10, 20, 30: received 1, 3, 5 | 12, 15, 20 | 25; rejected 3 and 20
    rx = np.array([1, 3, 5, 12, 15, 20, 25], np.int64)
    rej = np.array([3, 20], np.int64)
    acc = np.array([1, 5, 12, 15, 25], np.int64)
    received, rejected, upto, last = tick_health(rx, rej, acc, np.array([0, 10, 20, 30]))
    assert received.tolist() == [0, 3, 3, 1]
    assert rejected.tolist() == [0, 1, 1, 0]
    assert upto.tolist() == [0, 2, 4, 5]
    assert last.tolist() == [0, 5, 15, 25]
