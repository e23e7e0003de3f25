"""Sample validation: one test per rejection reason, split invariance, spike recovery."""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from monitor.config import FieldLimits, SensorLimits, default_config
from monitor.validate import REASONS, StreamValidator

S = 1_000_000_000
LIMITS = SensorLimits({"tension_N": FieldLimits(-100.0, 10_000.0, 1_000.0)}, stale_after_s=5.0)
NEVER = np.iinfo(np.int64).min


def verdicts(t_s, v, state=None, floor=NEVER):
    val = StreamValidator("tension", LIMITS, state)
    t = (np.asarray(t_s, dtype=np.float64) * S).astype(np.int64)
    codes = val.check(t, np.asarray(v, dtype=np.float64)[None, :], floor)
    return [("ok" if c == 0 else REASONS[c - 1]) for c in codes], val


def test_each_reason_is_detected_and_counted():
    # 1 kN/s allowed: +50 N in 0.1 s is 500 N/s (ok); +500 N in 0.1 s is 5 kN/s (spike)
    # verdicts compare with the last ACCEPTED sample (t = 0.1 until t = 0.5)
    t = [0.0, 0.1, 0.2, 0.3, 0.1, 0.05, 0.4, 0.5, 0.6]
    v = [1000, 1050, math.nan, 1550, 1050, 1050, 20_000, 1100, 1120]
    got, val = verdicts(t, v)
    assert got == ["ok", "ok", "nan", "spike", "duplicate", "time_backwards", "out_of_range",
                   "ok", "ok"]
    assert val.accepted == 4
    assert val.rejected == {"nan": 1, "out_of_range": 1, "spike": 1, "duplicate": 1,
                            "time_backwards": 1, "flat_line": 0, "check_factor": 0,
                            "time_ahead": 0}
    assert val.last_t_ns == int(0.6 * S) and val.last_values[0] == 1120


def test_duplicate_of_last_accepted_time_wins_over_other_checks():
    got, _ = verdicts([1.0, 1.0, 1.0], [5.0, math.nan, 1e9])
    assert got == ["ok", "duplicate", "duplicate"]


def test_spike_compares_with_last_accepted_sample_so_a_step_is_accepted_later():
    # a genuine 3 kN step: rejected until 1 kN/s * elapsed covers it (3 s after the last good)
    t = np.arange(0, 5.01, 0.5)
    v = np.where(t < 1.0, 1000.0, 4000.0)
    got, _ = verdicts(t, v)
    # last accepted at t=0.5 (1000 N); 4000 N is accepted once (t - 0.5) * 1000 >= 3000
    assert got == ["ok", "ok", "spike", "spike", "spike", "spike", "spike", "ok", "ok", "ok", "ok"]


def test_samples_at_or_before_the_processed_floor_are_time_backwards():
    got, _ = verdicts([1.0, 2.0, 3.0], [1.0, 1.0, 1.0], floor=2 * S)
    assert got == ["time_backwards", "time_backwards", "ok"]


def test_verdicts_and_state_are_split_invariant():
    rng = np.random.default_rng(7)
    n = 5000
    t = np.sort(rng.integers(0, 500 * S, n)).astype(np.int64)
    t[rng.integers(1, n, 100)] -= S  # some time going backwards
    v = 2000 + 500 * np.sin(np.arange(n) / 30) + rng.normal(0, 20, n)
    v[rng.integers(0, n, 50)] = np.nan
    v[rng.integers(0, n, 50)] += 3000  # spikes
    v[rng.integers(0, n, 20)] = 50_000  # out of range
    dup = rng.integers(1, n, 50)
    t[dup] = t[dup - 1]
    one = StreamValidator("tension", LIMITS)
    ref = one.check(t, v[None, :], NEVER)
    counts = np.bincount(ref, minlength=6)
    assert all(counts[1:] > 0), counts  # every reason occurs
    for trial in range(5):
        cuts = np.sort(rng.choice(np.arange(1, n), size=rng.integers(1, 60), replace=False))
        val = StreamValidator("tension", LIMITS)
        parts = []
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, n]):
            parts.append(val.check(t[a:b], v[None, a:b], NEVER))
            val = StreamValidator("tension", LIMITS, val.state())  # restore at every cut
        np.testing.assert_array_equal(np.concatenate(parts), ref)
        assert val.state() == one.state()


def test_multi_field_sample_is_rejected_if_any_field_is_bad():
    limits = SensorLimits({f: FieldLimits(-10.0, 10.0, math.inf)
                           for f in ("heave_m", "surge_m", "sway_m")}, 5.0)
    val = StreamValidator("motion", limits)
    t = np.array([0, S, 2 * S], dtype=np.int64)
    values = np.array([[0.0, 1.0, 2.0], [0.0, math.inf, 2.0], [0.0, 1.0, 11.0]])
    codes = val.check(t, values, NEVER)
    assert [REASONS[c - 1] if c else "ok" for c in codes] == ["ok", "nan", "out_of_range"]


def test_qartod_flags_are_counted_and_a_flat_line_fail_rejected():
    limits = SensorLimits({"tension_N": FieldLimits(
        -100.0, 10_000.0, 1_000.0, suspect_min=0.0, suspect_max=5_000.0, flat_tolerance=0.5,
        flat_suspect_s=1.0, flat_fail_s=2.0)}, stale_after_s=5.0)
    val = StreamValidator("tension", limits)
    # 0..0.9 s moving; 1.0..3.0 s stuck at 42 N; then above the operator span, then negative
    t = np.arange(40) * 0.1
    v = np.r_[np.arange(10) * 10.0, np.full(21, 42.0), 6000.0, 6001.0, -5.0, np.arange(6) * 7.0]
    codes = val.check((t * S).astype(np.int64), v[None, :], NEVER)
    got = [REASONS[c - 1] if c else "ok" for c in codes]
    # the flat window (values within 0.5 N) starts at 0.9 s (42 N after 90 N is no flat run):
    # stuck from 1.0 s; suspect once more than 1 s of it lies behind a sample, fail after 2 s
    assert got[:31] == ["ok"] * 30 + ["flat_line"]
    assert val.rejected["flat_line"] == 1
    assert val.qc_counts()["flat_line"] == {"suspect": 10, "fail": 1}
    assert val.qc_counts()["gross_range"] == {"suspect": 3, "fail": 0}
    # 42 -> 6000 N in 0.1 s: 59,580 N/s, over max_rate_per_s (rejected as spike as well)
    assert got[31] == "spike" and val.qc_counts()["rate_of_change"]["fail"] >= 1


def test_a_displacement_the_line_cannot_reach_is_a_location_fail():
    from monitor.config import default_config

    val = StreamValidator("motion", default_config().validate["motion"])
    # the seed 004 line: 40 m (40.8 m stretched 2 %) in 23 m, nominal span 29 m: the reach is
    # sqrt(40.8^2 - 23^2) = 33.70 m at heave 0, sqrt(40.8^2 - 21^2) = 34.98 m at heave -2 m
    heave = np.array([0.0, 0.0, -2.0, -2.0, 0.0, 0.0])
    surge = np.array([4.6, 4.8, 5.9, 6.1, -20.0, 0.0])
    sway = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 15.0])  # hypot(29, 15) = 32.65 m: reachable
    t = np.arange(6, dtype=np.int64) * 10 * S
    codes = val.check(t, np.stack([heave, surge, sway]), NEVER)
    assert [REASONS[c - 1] if c else "ok" for c in codes] == [
        "ok", "out_of_range", "ok", "out_of_range", "ok", "ok"]
    assert val.qc_counts()["location"] == {"suspect": 0, "fail": 2}


def _sequential_verdicts(t, values, lo, hi, rate, floor, qc_code, repeat):
    """The rules one sample at a time, as the module docstring states them (the oracle of
    the kernel, which accepts runs of samples at once)."""
    has_last, last_t, last_v, codes = False, 0, None, []
    for i, ti in enumerate(t.tolist()):
        v = values[:, i]
        if has_last and ti == last_t:
            code = 4
        elif (has_last and ti < last_t) or ti <= floor:
            code = 5
        elif repeat[i]:
            code = 4
        elif not np.all(np.isfinite(v)):
            code = 1
        elif np.any((v < lo) | (v > hi)):
            code = 2
        elif has_last and np.any(np.abs(v - last_v) > rate * ((ti - last_t) * 1e-9)):
            code = 3
        else:
            code = int(qc_code[i])
        codes.append(code)
        if code == 0:
            has_last, last_t, last_v = True, ti, v
    return codes


def test_runs_of_accepted_samples_give_the_sequential_verdicts():
    # three fields, every reason, the QC fails and repeats the pipeline passes in, against
    # the one-sample-at-a-time rules
    from monitor.validate import _validate

    rng = np.random.default_rng(11)
    n = 20_000
    t = np.cumsum(rng.integers(1, 2 * S // 10, n)).astype(np.int64)
    t[rng.integers(1, n, 80)] -= S
    dup = rng.integers(1, n, 60)
    t[dup] = t[dup - 1]
    values = 5 * np.sin(np.arange(n) / 20)[None, :] * np.array([[1.0], [0.5], [2.0]])
    values += rng.normal(0, 0.05, (3, n))
    for f in range(3):
        values[f, rng.integers(0, n, 30)] = rng.choice([np.nan, np.inf, -np.inf], 30)
        values[f, rng.integers(0, n, 30)] += 40.0  # spikes
        values[f, rng.integers(0, n, 10)] = 1e6  # out of range
    lo, hi, rate = np.array([-50.0, -30.0, -80.0]), np.array([50.0, 30.0, 80.0]), np.array(
        [200.0, 100.0, 300.0])
    qc_code = np.zeros(n, np.int8)
    qc_code[rng.integers(0, n, 40)] = 6
    qc_code[rng.integers(0, n, 40)] = 7
    repeat = np.zeros(n, np.bool_)
    repeat[rng.integers(0, n, 40)] = True
    floor = int(t[300])
    ref = _sequential_verdicts(t, values, lo, hi, rate, floor, qc_code, repeat)
    assert set(ref) == set(range(8)), sorted(set(ref))
    last_v = np.zeros(3)
    codes, counts, last_t, has_last = _validate(t, values, lo, hi, rate, np.int64(0), last_v,
                                                False, np.int64(floor), qc_code, repeat)
    assert codes.tolist() == ref
    assert counts.tolist() == np.bincount(ref, minlength=len(REASONS) + 1).tolist()
    accepted = np.flatnonzero(np.array(ref) == 0)
    assert has_last and last_t == t[accepted[-1]]
    np.testing.assert_array_equal(last_v, values[:, accepted[-1]])


SHARED = next((p / "shared" for p in Path(__file__).resolve().parents
               if (p / "shared/realdata").is_dir()), None)


def _blocks_through(sensor, t, values, cuts, monkeypatch, general, limits=None):
    """Verdicts of a stream cut into blocks at ``cuts`` (``limits``, default: the default
    limits of ``sensor``), the usual blocks through the one-call path, or (``general``) every
    block through the separate QC and validation calls; and how many took the one call."""
    import monitor.validate as validate

    usual = validate._check_usual
    took = [0]

    def spy(*args):
        out = (None,) if general else usual(*args)
        took[0] += bool(out[0])
        return (False,) + (None,) * 7 if general else out

    monkeypatch.setattr(validate, "_check_usual", spy)
    val = StreamValidator(sensor, limits or default_config().validate[sensor])
    codes = [val.check(t[a:b], values[:, a:b], NEVER).tolist()
             for a, b in zip(cuts[:-1], cuts[1:])]
    monkeypatch.setattr(validate, "_check_usual", usual)
    return codes, json.dumps(val.state()), val.qc_counts(), took[0]


def _one_call_equals_separate(sensor, t, values, cuts, monkeypatch, limits=None):
    fused = _blocks_through(sensor, t, values, cuts, monkeypatch, False, limits)
    separate = _blocks_through(sensor, t, values, cuts, monkeypatch, True, limits)
    assert fused[:3] == separate[:3]
    assert separate[3] == 0 and fused[3] >= len(cuts) // 2  # the one call did most blocks
    return fused


def test_the_usual_block_in_one_call_equals_the_separate_qc_and_validation(monkeypatch):
    """Tension at 20 Hz with NaN, infinities, spikes, a flat (stuck) stretch past the fail
    window, repeated and backward times, cut into random blocks: the one-call path of the
    usual block gives the verdicts, QC counts and state of the separate calls."""
    rng = np.random.default_rng(3)
    n = 40_000
    t = np.arange(n, dtype=np.int64) * 50_000_000
    v = 20_000 + 3_000 * np.sin(np.arange(n) / 40.0) + rng.normal(0, 200, n)
    v[rng.integers(0, n, 30)] = math.nan
    v[rng.integers(0, n, 5)] = math.inf
    v[rng.integers(0, n, 40)] += 30_000  # spikes
    v[10_000:23_000] = 21_000.0  # stuck for 650 s: flat-line suspect, then fail
    dup = rng.integers(1, n, 20)
    t[dup] = t[dup - 1]  # repeated times
    t[30_000:30_010] -= 2 * S  # a burst from the past
    cuts = np.unique(np.r_[0, rng.integers(1, n, 150), n]).tolist()
    codes, _, qc, _ = _one_call_equals_separate("tension", t, v[None, :], cuts, monkeypatch)
    flat = [c for block in codes for c in block].count(REASONS.index("flat_line") + 1)
    assert flat > 0 and qc["flat_line"]["suspect"] > 0 and qc["spike"]["fail"] > 0


EDGE = FieldLimits(-1e4, 1e4, 1000.0, suspect_min=-9000.0, suspect_max=9000.0,
                   spike_suspect=1.75, spike_fail=2.5, rate_suspect_per_s=100.0,
                   flat_tolerance=0.125, flat_suspect_s=0.1, flat_fail_s=0.3)
STEP = 50_000_000  # 20 Hz


def _edge_ramp(c, n=3000, field=EDGE, values=None, steps=None):
    """A ramp of 2 N a step through 0 at sample ``c - 1`` (nothing flagged: 40 N/s, spikes
    0, steps past the flat-line tolerance), edited at ``values`` ({index: value}) and the
    time ``steps`` ({index: ns since the sample before}), through the one-call path and the
    separate calls in three blocks: their QC counts (equal)."""
    x = 2.0 * (np.arange(n) - (c - 1))
    for i, v in (values or {}).items():
        x[i] = v
    dt = np.full(n, STEP, np.int64)
    for i, d in (steps or {}).items():
        dt[i] = d
    t = np.cumsum(dt)
    limits = SensorLimits({"tension_N": field}, stale_after_s=5.0)
    _, _, qc, took = _one_call_equals_separate("tension", t, x[None, :], [0, 100, 1500, n],
                                               pytest.MonkeyPatch(), limits)
    assert took == 2
    return {k: (c["suspect"], c["fail"]) for k, c in qc.items() if c["suspect"] or c["fail"]}


def _rate_step(dt_ns, r, flagged):
    """The step after 0 whose rate is just at ``r`` (``flagged`` False) or just past it."""
    dt = dt_ns * 1e-9
    d = r * dt
    while d / dt > r:
        d = np.nextafter(d, 0.0)
    while d / dt <= r:
        if not flagged:
            return d
        d = np.nextafter(d, np.inf)
    return d


def test_the_one_call_screen_is_exact_at_every_threshold():
    """Spans of a usual block the one-call path finds clear take no QC flags: samples at
    each threshold's edge and one float past it, inside a ramp that is otherwise clear,
    give the separate calls' flags and verdicts (a screen a float too loose or too tight
    on any test differs from them)."""
    c = 700  # mid-span of the second block (spans from 102, 1126)
    ramp = {k: 2.0 * (k - c + 1) + 4.0 for k in range(c + 1, 3000)}  # after a 5 N step
    assert _edge_ramp(c) == {}
    # rate of change: a 5 N step exactly at 100 N/s, a float more, and a step whose rate
    # rounds past 100 N/s though the step is within fl(100 * dt)
    assert _edge_ramp(c, values={c: _rate_step(STEP, 100.0, False), **ramp}) == {}
    assert _edge_ramp(c, values={c: _rate_step(STEP, 100.0, True), **ramp}) == {
        "rate_of_change": (1, 0)}
    odd = next(ns for ns in range(STEP, STEP + 1000) if (100.0 * (ns * 1e-9)) / (ns * 1e-9) > 100.0)
    assert _edge_ramp(c, values={c: 100.0 * (odd * 1e-9), **ramp}, steps={c: odd}) == {
        "rate_of_change": (1, 0)}
    # spike: 1.75 N off the line through its neighbours, and a float more
    assert _edge_ramp(c, values={c - 1: 1.75}) == {}
    assert _edge_ramp(c, values={c - 1: np.nextafter(1.75, 2.0)}) == {"spike": (1, 0)}
    # gross range: the suspect span starting at the first screened sample (102; every
    # sample before is below it), or a float above it
    x102 = 2.0 * (102 - (c - 1))
    edge = dict(suspect_min=x102)
    assert _edge_ramp(c, field=dataclasses.replace(EDGE, **edge)) == {"gross_range": (102, 0)}
    edge = dict(suspect_min=np.nextafter(x102, np.inf))
    assert _edge_ramp(c, field=dataclasses.replace(EDGE, **edge)) == {"gross_range": (103, 0)}
    top = 2.0 * (2999 - (c - 1))  # the last sample, screened
    assert _edge_ramp(c, field=dataclasses.replace(EDGE, suspect_max=top)) == {}
    edge = dict(suspect_max=np.nextafter(top, 0.0))
    assert _edge_ramp(c, field=dataclasses.replace(EDGE, **edge)) == {"gross_range": (1, 0)}
    # a subnormal rate bound: its product with the step rounds up to the step
    tiny = FieldLimits(-1e4, 1e4, 1000.0, rate_suspect_per_s=5e-323)
    bump = {**{k: 0.0 for k in range(3000)}, c: 5e-324}
    assert _edge_ramp(c, field=tiny, values=bump) == {"rate_of_change": (2, 0)}
    # flat line: two steps of 0.0625 N (under the 0.125 N tolerance) span it exactly, over
    # exactly the 0.1 s window: a pass; over a nanosecond more (both small steps then reach
    # back past the window), or spanning less: suspect
    flat = {c - 1: -1.9375, c: -1.875,
            **{k: -1.875 + 2.0 * (k - c) for k in range(c + 1, 3000)}}
    assert _edge_ramp(c, values=flat) == {}
    assert _edge_ramp(c, values=flat, steps={c - 1: STEP + 1}) == {"flat_line": (2, 0)}
    assert _edge_ramp(c, values={**flat, c: -1.8828125}) == {"flat_line": (1, 0)}
    # a 0.15 s gap: the step is past the tolerance but not within the window
    assert _edge_ramp(c, steps={c: 150_000_000}) == {"flat_line": (1, 0)}


def test_the_one_call_kernel_keeps_the_validators_own_limits():
    """The one-call kernel given a validator span and rate narrower than the QC's fail
    thresholds (which they equal in a StreamValidator): its verdicts, QC counts and memory
    are those of the separate QC and validation kernels."""
    from monitor import validate
    from monitor.qartod import FLAT_MEMORY, _params, _qc_fast

    n = 5000
    t = np.arange(1, n + 1, dtype=np.int64) * STEP
    # down 2 N a step through the validator's floor and back up through its ceiling
    x = 2.0 * np.abs(np.arange(n) - 2000.0) - 2000.0
    x[3200:] += 1.0  # a 3 N step: past the validator's 2.5 N a step, not the QC's 5 N
    x[[3500, 3700]] += 0.75  # ... and two small spikes (crossings and these in other spans)
    p = _params((EDGE,))
    lo, hi, rate = np.array([0.0]), np.array([3000.0]), np.array([50.0])
    outs = []
    for fused in (True, False):
        ring_t, ring_x = np.zeros(FLAT_MEMORY, np.int64), np.full((1, FLAT_MEMORY), np.nan)
        prev, prev2, last_v = np.array([2002.0]), np.array([2004.0]), np.array([2002.0])
        args = (np.int64(0), prev, prev2, ring_t, ring_x, np.int64(0), np.int64(0),
                np.int64(-STEP))
        if fused:
            ok, qc_counts, head, ring_n, codes, counts, last_t, has = validate._check_usual(
                t, x[None, :], np.int64(-1), p, *args, lo, hi, rate, np.int64(0), last_v,
                True)
        else:
            ok, flags, _, qc_counts, head, ring_n = _qc_fast(t, x[None, :], p, *args)
            codes, counts, last_t, has = validate._validate(
                t, x[None, :], lo, hi, rate, np.int64(0), last_v, True, np.int64(-1),
                validate._fail_codes(flags), np.zeros(n, np.bool_))
        assert ok
        outs.append((codes.tolist(), counts.tolist(), qc_counts.tolist(), int(head),
                     int(ring_n), int(last_t), bool(has), last_v.tolist(), ring_t.tolist()))
    assert outs[0] == outs[1]
    codes = np.array(outs[0][0])
    assert (codes == REASONS.index("out_of_range") + 1).sum() == 1999 + 500  # under, over
    assert (codes == REASONS.index("spike") + 1).sum() == 3  # the step, a spike and back


@pytest.mark.skipif(SHARED is None, reason="../shared/realdata absent")
def test_the_one_call_path_on_real_records(monkeypatch):
    """The Maine end-line load cell (tension, real gaps and hauls) and the Spotter's
    displacements fed as a three-field IMU stream: one call equals the separate calls."""
    lc = np.genfromtxt(SHARED / "realdata/maine_endline_loadcell/lc_data.csv", delimiter=",",
                       skip_header=1, usecols=(1, 2))
    t = np.rint(lc[:, 0] * 1e9).astype(np.int64)
    cuts = list(range(0, t.shape[0], 997)) + [t.shape[0]]
    _one_call_equals_separate("tension", t, lc[:, 1][None, :] * 4.4482216152605, cuts,
                              monkeypatch)
    d = np.genfromtxt(SHARED / "realdata/spotter_clallam_1945/0026_FLT.CSV", delimiter=",",
                      skip_header=1, usecols=(1, 2, 3, 4))
    t = np.rint((d[:, 0] - d[0, 0]) * 1e9).astype(np.int64)
    cuts = list(range(0, t.shape[0], 1500)) + [t.shape[0]]
    _one_call_equals_separate("imu", t, np.ascontiguousarray(d[:, 1:].T / 1000.0), cuts,
                              monkeypatch)
