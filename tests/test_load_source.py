"""monitor.load_source.LoadSelector: which estimated samples feed fatigue."""

import msgspec
import numpy as np
import pytest

from monitor.config import default_config
from monitor.load_source import ESTIMATED, MEASURED, LoadSelector, build_estimator

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
    cfg = msgspec.structs.replace(default_config().load, source="auto", stale_after_s=5.0)
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


@pytest.mark.parametrize("source", ["auto", "estimated"])
def test_clamped_estimates_that_feed_fatigue_are_counted(source):
    """Estimates of motion outside the model's range (held at its edge) are used, and the
    ones used are counted; the count is saved with the state."""
    cfg = msgspec.structs.replace(default_config().load, source=source, stale_after_s=5.0)
    sel = LoadSelector(cfg, {"last_measured_ns": None})  # a state from before the count
    e_t = np.arange(1, 41, dtype=np.int64) * (S // 10)  # 4 s of estimates, no tension
    e_v = np.full(e_t.shape, 800.0)
    clamped = np.zeros(e_t.shape, bool)
    clamped[[3, 4, 5, 30]] = True
    t, v, src = sel.select(np.zeros(0, np.int64), np.zeros(0), e_t, e_v, clamped)
    assert sel.estimates_clamped == 4
    np.testing.assert_array_equal(t, e_t)
    assert np.all(src == ESTIMATED)
    again = LoadSelector(cfg, sel.state())
    assert again.estimates_clamped == 4 and again.last_measured_ns == sel.last_measured_ns
    if source == "auto":
        # with a live load cell the estimates are not used: clamped ones are not counted
        m_t = e_t[-1] + np.arange(1, 21, dtype=np.int64) * (S // 20)
        e2 = m_t[::2] + 1
        sel.select(m_t, np.full(m_t.shape, 900.0), e2, np.full(e2.shape, np.nan),
                   np.ones(e2.shape, bool))
        assert sel.estimates_clamped == 4


def _motion_run(heave):
    from monitor.blocks import SampleBlock
    from monitor.config import config_with
    from monitor.pipeline import Pipeline

    c = default_config()
    config = config_with(c, load={**c.raw["load"], "source": "estimated",
                                  "motion_sensor": "motion"})
    n = heave.shape[0]
    t = 1_700_000_000 * S + np.arange(n, dtype=np.int64) * (S // 10)
    k = np.arange(n)
    surge, sway = 0.3 * np.sin(k / 40.0), 0.1 * np.cos(k / 55.0)
    p = Pipeline(config, horizon_s=3600.0, gate_all=True)
    for a in range(0, n, 100):
        p.process(SampleBlock("vaps", "motion", t[a:a + 100], {
            "heave_m": heave[a:a + 100], "surge_m": surge[a:a + 100], "sway_m": sway[a:a + 100]}))
    p.flush()
    assert p.status()["estimates_clamped"] == p.report()["tension_N"]["samples_estimate_clamped"]
    return p.report()


def test_motion_outside_the_estimators_table_is_counted_as_clamped():
    """A slow heave excursion to 4 m passes validation (it is no spike) but lies outside the
    estimator's tension table (+-2 m): its samples feed fatigue at the table's edge value and
    the report counts them."""
    n = 6000
    k = np.arange(n)
    calm = 0.5 * np.sin(2 * np.pi * k / 52.5)
    excursion = calm + np.where((k > 3000) & (k < 3400), 4.0 * np.sin(np.pi * (k - 3000) / 400), 0)
    a, b = _motion_run(calm), _motion_run(excursion)
    outside = int(np.count_nonzero(excursion > 2.0))
    assert a["tension_N"]["samples_estimate_clamped"] == 0
    assert b["tension_N"]["samples_estimate_clamped"] == outside > 100
    assert b["tension_N"]["samples_estimated"] == a["tension_N"]["samples_estimated"]
    assert b["samples"]["motion"]["accepted"] == n and b["samples"]["motion"]["rejected"]["spike"] == 0


def _displacement(n: int, t0_s: float, offset_m: float) -> tuple[np.ndarray, dict]:
    k = np.arange(n)
    t = np.rint((t0_s + 0.1 * k) * 1e9).astype(np.int64)
    heave = 0.5 * np.sin(2 * np.pi * k / 52.5)
    return t, {"heave_m": heave, "surge_m": offset_m + 0.3 * heave, "sway_m": 0.1 * heave}


def test_a_gap_longer_than_stale_restarts_the_estimator():
    """After 20 s of silence (motion stale_after_s = 5 s) the stream resumes 8 m further
    surge: the estimate after the gap is exactly that of a fresh estimator fed only the
    samples after it (its first two settle), not a jump of 8 m differenced as one 0.1 s
    step; any split of the stream into blocks, with the state saved between, gives the same."""
    cfg = default_config()
    t1, f1 = _displacement(300, 0.0, 0.0)
    t2, f2 = _displacement(300, 49.9, 8.0)  # 20 s after t1's last sample
    t = np.concatenate([t1, t2])
    f = {k: np.concatenate([f1[k], f2[k]]) for k in f1}
    e_t, e_v, _ = build_estimator(cfg, sensor="motion").feed(t, f)
    fresh_t, fresh_v, _ = build_estimator(cfg, sensor="motion").feed(t2, f2)
    assert fresh_t.shape[0] == 298 and np.array_equal(fresh_t, e_t[-298:])
    assert np.array_equal(fresh_v, e_v[-298:])  # bit for bit
    assert e_t.shape[0] == 2 * 298
    # across the gap, without the restart, the 8 m step would be one 80 m/s difference
    joined_t = np.concatenate([t1, t2 - t2[0] + t1[-1] + 100_000_000])
    _, joined_v, _ = build_estimator(cfg, sensor="motion").feed(joined_t, f)
    assert joined_v[298] > 5 * e_v.max()
    # split anywhere (the gap inside a block, or at a block's first sample), state saved
    for cut in (150, 300, 301, 450):
        a = build_estimator(cfg, sensor="motion")
        out_a = a.feed(t[:cut], {k: v[:cut] for k, v in f.items()})
        b = build_estimator(cfg, a.state(), sensor="motion")
        out_b = b.feed(t[cut:], {k: v[cut:] for k, v in f.items()})
        assert np.array_equal(np.concatenate([out_a[0], out_b[0]]), e_t)
        assert np.array_equal(np.concatenate([out_a[1], out_b[1]]), e_v)


def test_feed_returns_the_wanted_estimates_and_the_newest_sample():
    """With a ``want`` mask the estimator returns the wanted samples' estimates, bit for bit
    those of a feed wanting every sample, and the newest sample of the block (NaN when not
    wanted: the status dates the stream's newest estimate by it); the stream state is the
    same either way. The settling samples (a stream's first two) give none."""
    cfg = default_config()
    t, f = _displacement(300, 0.0, 0.0)
    every = build_estimator(cfg, sensor="motion")
    ref_t, ref_v, ref_c = every.feed(t, f)
    some = build_estimator(cfg, sensor="motion")
    rng = np.random.default_rng(7)
    got = []
    for a, b in ((0, 100), (100, 220), (220, 300)):
        want = rng.random(b - a) < 0.2
        want[0] = True  # the block's first (settling in the first block: no estimate)
        want[-1] = b == 300  # the last block's newest is wanted, the others' not
        e_t, e_v, e_c = some.feed(t[a:b], {k: v[a:b] for k, v in f.items()}, want)
        first = 2 if a == 0 else 0
        expected = np.flatnonzero(want)
        expected = np.append(expected[expected >= first], b - a - 1) if b < 300 else \
            expected[expected >= first]
        np.testing.assert_array_equal(e_t, t[a:b][expected])
        ref = np.searchsorted(ref_t, e_t)
        np.testing.assert_array_equal(e_v[:-1], ref_v[ref[:-1]])
        np.testing.assert_array_equal(e_c, ref_c[ref] & ~np.isnan(e_v))
        if b < 300:
            assert np.isnan(e_v[-1]) and not e_c[-1]
        else:
            assert e_v[-1] == ref_v[-1]
        got.append(e_v)
    assert every.state() == some.state()
