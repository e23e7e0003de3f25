"""monitor.late_copies in the pipeline: a late exact copy of an accepted sample (a publisher
re-sending its cache) is a ``duplicate``, outside the rejected rate; a late sample that is no
copy stays ``time_backwards``; what it keeps survives a saved state (the daemon with a real
re-sending publisher: tests/test_daemon_late_copies.py)."""

from __future__ import annotations

import json
import zlib
from pathlib import Path

import numpy as np

from monitor.blocks import SampleBlock
from monitor.config import config_with, load_config
from monitor.pipeline import Pipeline

SHIPPED = Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml"
T0_NS = 1_750_000_000 * 10**9


def _config():
    shipped = load_config(SHIPPED)
    return config_with(shipped, ordering={"copy_span_s": 35.0},
                       load={**shipped.raw["load"], "source": "measured"})


def block(k: int, bump: float = 0.0) -> SampleBlock:
    """Second ``k`` of 20 Hz tension (``bump``: the same times, other values)."""
    t = T0_NS + k * 10**9 + 50_000_000 * np.arange(20, dtype=np.int64)
    x = 3000.0 + 100.0 * np.sin(np.arange(20.0) + k) + bump
    return SampleBlock("vaps", "tension", t, {"tension_N": x}, int(t[-1]))


def feed(p: Pipeline, blocks) -> list[tuple[str, str, str]]:
    return [(r.rule, r.component, r.event) for b in blocks for r in p.process(b).alerts
            if r.rule == "rejected_rate"]


def rejected(p: Pipeline) -> dict[str, int]:
    return {r: n for r, n in p.validators["tension"].rejected.items() if n}


def late_sends(p: Pipeline) -> list[tuple[dict[str, int], list]]:
    """After 60 s of tension (live horizon 10 s): the 10 s from 30 s re-sent exactly, then the
    5 s from 2 s (older than the 35 s span) re-sent exactly, then 10 s from 40 s re-sent with
    other values; each followed by new data that evaluates the ticks."""
    out = []
    for late, new in (([block(k) for k in range(30, 40)], range(60, 80)),
                      ([block(k) for k in range(2, 7)], range(80, 85)),
                      ([block(k, 1.0) for k in range(40, 50)], range(85, 100))):
        fired = feed(p, late) + feed(p, (block(k) for k in new))
        out.append((rejected(p), fired))
    return out


def test_late_exact_copies_are_duplicates_other_late_samples_time_backwards():
    p = Pipeline(_config(), horizon_s=10.0)
    assert feed(p, (block(k) for k in range(60))) == []
    copies, too_old, other_values = late_sends(p)
    # was: {"time_backwards": 200} and rejected_rate fired (200 of ~1,400 samples in 600 s)
    assert copies == ({"duplicate": 200}, [])
    # beyond the span: not kept, so no copy known (a bounded memory)
    assert too_old == ({"duplicate": 200, "time_backwards": 100}, [("rejected_rate", "tension",
                                                                   "fire")])
    assert other_values[0] == {"duplicate": 200, "time_backwards": 300}
    assert p.validators["tension"].accepted == 100 * 20


def test_what_it_keeps_is_in_the_state_and_a_restored_pipeline_judges_the_same():
    one = Pipeline(_config(), horizon_s=10.0)
    feed(one, (block(k) for k in range(60)))
    first = Pipeline(_config(), horizon_s=10.0)
    feed(first, (block(k) for k in range(45)))
    saved = json.loads(json.dumps(first.state()))
    assert sorted(saved["late_copies"]) == ["tension"]
    second = Pipeline(_config(), state=saved, horizon_s=10.0)
    feed(second, (block(k) for k in range(45, 60)))
    assert json.dumps(one.state(), sort_keys=True) == json.dumps(second.state(), sort_keys=True)
    assert late_sends(second) == late_sends(one)
    # a state without it (written before) starts with nothing kept: copies are late samples
    del saved["late_copies"]
    old = Pipeline(_config(), state=saved, horizon_s=10.0)
    feed(old, [block(k) for k in range(45, 50)] + [block(k) for k in range(30, 35)])
    assert rejected(old) == {"time_backwards": 100}


def test_the_slabs_of_each_minute_are_joined_and_the_span_cut_at_a_whole_minute():
    """Live slabs are tiny (a second of tension: 0.3 kB of samples, as much in array
    headers): a minute's parts are joined once the next begins, and what is kept starts at
    the minute the span reaches back to, whatever the parts."""
    from monitor.late_copies import LateCopies

    lc = LateCopies(90.0)
    blocks = [block(k) for k in range(200)]  # T0 is 40 s into a minute
    for b in blocks:
        lc.received("tension", b.t_ns, b.fields["tension_N"][None, :], np.zeros(20, np.int8))
    acc = lc._streams["tension"]
    # kept from 80 s on (the minute 90 s before the newest): the minute from 80 s joined, and
    # the 60 one-second slabs of the minute from 140 s, not yet over (unjoined: 120 parts)
    assert len(acc.parts) == 61
    t, values = acc.within(lc.span_ns)
    newest = int(blocks[-1].t_ns[-1])
    cut = (newest - 90 * 10**9) // (60 * 10**9) * 60 * 10**9
    every_t = np.concatenate([b.t_ns for b in blocks])
    every_v = np.concatenate([b.fields["tension_N"] for b in blocks])
    assert np.array_equal(t, every_t[every_t >= cut])
    assert np.array_equal(values[0], every_v[every_t >= cut])
    assert t[0] == cut  # a sample on the minute itself


def imu_block(k: int) -> SampleBlock:
    """Second ``k`` of 10 Hz IMU (three fields)."""
    t = T0_NS + k * 10**9 + 100_000_000 * np.arange(10, dtype=np.int64)
    a = np.arange(10.0) + k
    return SampleBlock("vaps", "imu", t, {"accel_x_mps2": 0.1 * np.sin(a),
                                          "accel_y_mps2": 0.1 * np.cos(a),
                                          "accel_z_mps2": 9.81 + 0.01 * np.sin(2 * a)}, int(t[-1]))


def test_a_late_copy_of_a_rejected_sample_nan_too_is_a_duplicate_on_any_stream():
    """A re-sent cache holds the samples rejected the first time too (a NaN dropout, a value
    out of range): their copies are duplicates as well (the first verdict was counted), a NaN
    matching a NaN (NaN != NaN: was time_backwards, a 10-min NaN dropout re-sent fired
    rejected_rate). A late NaN where a value was is no copy."""
    def send(k: int, nan_imu: bool = False) -> list[SampleBlock]:
        t, imu = block(k), imu_block(k)
        if k == 35:  # two tension samples missing, one far out of range; an IMU field missing
            t.fields["tension_N"][[3, 4]] = np.nan
            t.fields["tension_N"][9] = 1e9
            imu.fields["accel_y_mps2"][2] = np.nan
        if nan_imu:
            imu.fields["accel_x_mps2"][5] = np.nan
        return [imu, t]  # the IMU first: tension gates (it would pass the IMU by)

    p = Pipeline(_config(), horizon_s=10.0)
    for k in range(60):
        feed(p, send(k))
    first = {s: {r: n for r, n in p.validators[s].rejected.items() if n}
             for s in ("tension", "imu")}
    assert first == {"tension": {"nan": 2, "out_of_range": 1}, "imu": {"nan": 1}}
    for k in range(30, 40):  # re-sent exactly, 20 to 30 s behind the processed time
        feed(p, send(k))
    feed(p, send(40, nan_imu=True))  # a NaN where a value was accepted: no copy
    for k in range(60, 70):
        feed(p, send(k))
    got = {s: {r: n for r, n in p.validators[s].rejected.items() if n} for s in ("tension", "imu")}
    # was tension 197 duplicates + 3 time_backwards, imu 99 + 1
    assert got == {"tension": {"nan": 2, "out_of_range": 1, "duplicate": 220},
                   "imu": {"nan": 1, "duplicate": 109, "time_backwards": 1}}


def test_a_restored_stream_keeps_no_more_than_one_that_never_stopped():
    """Restored per minute, the kept minutes stay apart: the slabs after them join only their
    own minute, so the oldest minute goes as the span moves on (was: every restored minute
    joined into one part with the first new minute, kept whole until its newest sample left
    the span: 190 s of samples held for a 90-s span)."""
    from monitor.late_copies import LateCopies

    def add(lc, ks):
        for k in ks:
            b = block(k)
            lc.received("tension", b.t_ns, b.fields["tension_N"][None, :], np.zeros(20, np.int8))

    never, first = LateCopies(90.0), LateCopies(90.0)
    add(never, range(270))
    add(first, range(200))  # T0 is 40 s into a minute: minutes from 120 and 180 s kept
    restored = LateCopies(90.0, json.loads(json.dumps(first.state())))
    add(restored, range(200, 270))  # the span reaches back to the minute from 180 s
    held = [sum(p[0].shape[0] for p in lc._streams["tension"].parts) for lc in (never, restored)]
    assert held[1] == held[0] <= 20 * (90 + 60)
    assert all(np.array_equal(a, b) for a, b in zip(never._streams["tension"].within(never.span_ns),
                                                   restored._streams["tension"].within(never.span_ns)))


def _span_150():
    return config_with(_config(), ordering={"copy_span_s": 150.0})


def _late_copies_of(p: Pipeline, seconds) -> dict[str, int]:
    """``rejected`` after re-sending ``seconds`` exactly, then 20 s of new data."""
    before = p.validators["tension"].rejected.copy()
    after = p.validators["tension"]
    feed(p, [block(k) for k in seconds] + [block(k) for k in range(200, 220)])
    return {r: n - before[r] for r, n in after.rejected.items() if n - before[r]}


def _saved_and_restored(tmp_path, damage=None) -> Pipeline:
    """200 s of tension (minutes from 20, 80 and 140 s kept for the 150-s span: the first two
    closed) checkpointed by the daemon's store, ``damage(db, keys)`` done to the file, and the
    pipeline restored from it."""
    import sqlite3  # noqa: PLC0415

    from monitor.checkpoint import CheckpointStore  # noqa: PLC0415

    first = Pipeline(_span_150(), horizon_s=10.0)
    feed(first, (block(k) for k in range(200)))
    store = CheckpointStore(tmp_path / "state.sqlite")
    store.save({"pipeline": first.state()})
    store.close()
    if damage is not None:
        db = sqlite3.connect(tmp_path / "state.sqlite")
        row = db.execute("SELECT state FROM checkpoint").fetchone()[0]
        saved = json.loads(zlib.decompress(row))
        damage(db, saved["pipeline"]["late_copies"]["tension"])
        db.commit()
        db.close()
    store = CheckpointStore(tmp_path / "state.sqlite")
    restored = Pipeline(_span_150(), state=store.load().state["pipeline"], horizon_s=10.0)
    store.close()
    return restored


def test_restored_from_the_daemon_store_judges_as_one_that_never_stopped(tmp_path):
    """Saved with its closed minutes as write-once parts and restored from them: the same
    state as a pipeline that never stopped, and the same verdicts on late copies."""
    never = Pipeline(_span_150(), horizon_s=10.0)
    feed(never, (block(k) for k in range(200)))
    restored = _saved_and_restored(tmp_path)
    assert restored.late_copies.lost == {}
    assert json.dumps(never.state(), sort_keys=True) == json.dumps(restored.state(),
                                                                 sort_keys=True)
    seconds = [*range(30, 40), *range(90, 100), *range(150, 160)]
    assert _late_copies_of(never, seconds) == _late_copies_of(restored, seconds) == {
        "duplicate": 600}
    assert json.dumps(never.state(), sort_keys=True) == json.dumps(restored.state(),
                                                                 sort_keys=True)


def test_a_missing_or_damaged_saved_minute_loses_only_its_late_copies(tmp_path, caplog):
    """A closed minute's part gone from the checkpoint file, or another's damaged: was a
    KeyError / zlib.error at start-up. Now the pipeline starts, logs it, counts it per stream
    (``late_copies.lost``: the daemon's status and metrics), and only late copies of those
    minutes are time_backwards (as with no late copies kept); the other minutes' are
    duplicates, as in a pipeline that never stopped."""
    def gone(db, saved):  # the values of the minute from 80 s missing
        db.execute("DELETE FROM parts WHERE key = ?", (saved["v"][1]["k"],))

    with caplog.at_level("ERROR", logger="monitor.late_copies"):
        p = _saved_and_restored(tmp_path / "a", gone)
    assert p.late_copies.lost == {"tension": 1}
    [rec] = caplog.records
    assert rec.getMessage().startswith("late copies not restored")
    assert rec.fields["minutes_lost"] == {"tension": 1}
    assert _late_copies_of(p, [*range(30, 40), *range(90, 100), *range(150, 160)]) == {
        "duplicate": 400, "time_backwards": 200}

    def damaged(db, saved):  # the minute from 20 s: times rewritten, the hash no longer fits
        db.execute("UPDATE parts SET data = 'AAAA' || substr(data, 5) WHERE key = ?",
                   (saved["t"][0]["k"],))

    p = _saved_and_restored(tmp_path / "b", damaged)
    assert p.late_copies.lost == {"tension": 1}
    assert _late_copies_of(p, [*range(30, 40), *range(90, 100), *range(150, 160)]) == {
        "duplicate": 400, "time_backwards": 200}


def test_a_saved_state_with_unreadable_late_copies_restores_the_rest():
    """The same faults inline (a replay's state file, edited or cut): not base64, not
    deflated, the wrong shape, lists of unequal length or no "v" list, a stream unknown: each
    loses its minutes (or its stream), nothing else; was a KeyError / binascii / zlib /
    reshape error."""
    from monitor.late_copies import _pack  # noqa: PLC0415

    first = Pipeline(_span_150(), horizon_s=10.0)
    feed(first, (block(k) for k in range(200)))
    saved = json.loads(json.dumps(first.state()))
    good = saved["late_copies"]["tension"]
    cases = [({"t": ["%%%", *good["t"][1:]], "v": good["v"]}, 1, 400),
             ({"t": good["t"], "v": [good["v"][0], "AAAA", good["v"][2]]}, 1, 400),
             ({"t": good["t"], "v": [_pack(np.zeros(7)), *good["v"][1:]]}, 1, 400),
             ({"t": good["t"], "v": good["v"][:-1]}, 1, 0),
             ({"t": good["t"]}, 1, 0)]
    for late, lost, duplicates in cases:
        p = Pipeline(_span_150(), state={**saved, "late_copies": {"tension": late, "radar": 1}},
                     horizon_s=10.0)
        assert p.late_copies.lost == {"tension": lost, "radar": 1}
        got = _late_copies_of(p, [*range(30, 40), *range(90, 100), *range(150, 160)])
        assert got.get("duplicate", 0) == duplicates
        assert got.get("duplicate", 0) + got.get("time_backwards", 0) == 600
        # the rest of the state restored: the counts before the re-send are the saved ones
        assert p.validators["tension"].accepted == 220 * 20
