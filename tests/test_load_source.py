"""monitor.load_source.LoadSelector: which estimated samples feed fatigue."""

import dataclasses

import numpy as np
import pytest

from monitor.config import default_config
from monitor.load_source import ESTIMATED, MEASURED, LoadSelector

S = 1_000_000_000


def reference_use(m_t, e_t, prev, stale_ns):
    """The rule, one sample at a time: an estimate is used iff no accepted tension sample
    lies in [e - stale, e] (the previous slabs' newest one counts too)."""
    known = ([prev] if prev is not None else []) + [int(m) for m in m_t]
    out = []
    for e in e_t:
        latest = max((m for m in known if m <= e), default=None)
        if latest is None:
            latest = prev  # an estimate older than everything seen: only prev can cover it
        out.append(latest is None or e - latest > stale_ns)
    return np.array(out, dtype=bool)


@pytest.mark.parametrize("seed", range(40))
def test_needed_matches_the_rule_and_select_uses_exactly_those(seed):
    rng = np.random.default_rng(seed)
    cfg = dataclasses.replace(default_config().load, source="auto", stale_after_s=5.0)
    sel = LoadSelector(cfg)
    stale_ns = sel.stale_ns
    t0 = 0
    for _ in range(6):  # consecutive slabs, with and without gaps, sometimes no tension
        n_m = int(rng.integers(0, 60))
        steps = rng.choice([S // 20, S // 20, 7 * S], size=n_m, p=[0.6, 0.35, 0.05])
        m_t = t0 + np.cumsum(steps).astype(np.int64)
        e_t = np.sort(t0 + rng.integers(0, max(int(m_t[-1] - t0) if n_m else 20 * S, 1) + 10 * S,
                                        size=int(rng.integers(1, 40)))).astype(np.int64)
        e_t = np.unique(e_t)
        expected = reference_use(m_t, e_t, sel.last_measured_ns, stale_ns)
        use = sel.needed(m_t, e_t)
        np.testing.assert_array_equal(use, expected)
        e_v = np.where(use, 1000.0 + np.arange(e_t.size), np.nan)  # unneeded: never used
        t, v, src = sel.select(m_t, np.full(m_t.shape, 5.0), e_t, e_v)
        assert not np.isnan(v).any()
        assert (src == ESTIMATED).sum() == use.sum() and (src == MEASURED).sum() == n_m
        assert np.all(np.diff(t) >= 0)
        t0 = int(max(m_t[-1] if n_m else 0, e_t[-1]))
