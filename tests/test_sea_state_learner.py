"""The learner's per-window Welch sums (monitor.sea_state_learner): the same bits for any
split of the stream into slabs, across a state save, as the direct computation of each
window's segments (models.fatigue.spectral.segment_psds, summed in time order)."""

from __future__ import annotations

import contextlib
import json

import numpy as np
import pytest

from models._jit import uncompiled
from models.fatigue.spectral import segment_psds
from monitor.sea_state_learner import SEGMENT, _WindowSpectra

W_NS = 300 * 10**9  # five-minute windows: five whole 20 Hz segments (51.2 s) each
NAMES = ("a", "b")


def stream(b: str = "own") -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Two stresses (a 0.1 Hz swell and noise) over five-minute windows: the first whole at
    20 Hz (five segments and 880 samples left open at its end); the second with a 2 s gap
    in its second segment (whose rate is then 4 % off: dropped); none in the third; the
    fourth at 10 Hz (its own rate: kept); the fifth with one 20 Hz segment and some
    samples more. ``b``: "own" its own stress, "same" a copy of a's, "parts" a copy of
    a's until 450 s (in the second window's third segment), then its own, "blip" a copy of
    a's but for its own from 450 to 450.3 s."""
    rng = np.random.default_rng(5)
    t0 = 8_333 * W_NS

    def at(start_s: float, stop_s: float, dt_s: float) -> np.ndarray:
        n = round((stop_s - start_s) / dt_s)
        return t0 + round(start_s * 1e9) + np.arange(1, n + 1, dtype=np.int64) * round(dt_s * 1e9)

    t = np.concatenate([at(0, 300, 0.05), at(300, 360, 0.05), at(362, 600, 0.05),
                        at(900, 1200, 0.1), at(1200, 1300, 0.05)])
    swell = np.sin(2 * np.pi * 0.1 * (t - t0) / 1e9)
    x = {"a": 3e6 * swell + 2e5 * rng.normal(size=t.size) + 1e7,
         "b": 1e6 * swell + 5e4 * rng.normal(size=t.size)}
    own = {"own": t > 0, "same": t < 0, "parts": t - t0 > 450 * 10**9,
           "blip": (t - t0 > 450 * 10**9) & (t - t0 <= 450_300_000_000)}[b]
    x["b"] = np.where(own, x["b"], x["a"])
    return t, x


def reference(t: np.ndarray, x: dict[str, np.ndarray]) -> dict[int, dict]:
    """Per window: the sums of its good segments' periodograms, one row after another."""
    out = {}
    index = -(-t // W_NS)
    for k in np.unique(index).tolist():
        tt = t[index == k]
        full = tt.size // SEGMENT * SEGMENT
        seg_t = tt[:full].reshape(-1, SEGMENT)
        spans = (seg_t[:, -1] - seg_t[:, 0]) / 1e9
        fs = (SEGMENT - 1) / spans
        good = np.abs(fs / fs[0] - 1.0) <= 0.02
        sums = {}
        for n in NAMES:
            _, rows = segment_psds(x[n][index == k][:full].reshape(-1, SEGMENT)[good], fs[0])
            acc = rows[0]
            for row in rows[1:]:
                acc = acc + row
            sums[n] = acc
        out[k] = {"fs": fs[0], "segments": int(good.sum()), "dropped": int((~good).sum()),
                  "psd": sums, "open": tt[full:]}
    return out


def feed_in(pieces: list[int], save_at: int | None = None, b: str = "own"
            ) -> dict[int, object]:
    t, x = stream(b)
    spectra = _WindowSpectra(NAMES, W_NS)
    windows = {}
    bounds = np.cumsum([0, *pieces])
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        if i == save_at:
            spectra = _WindowSpectra(NAMES, W_NS, json.loads(json.dumps(spectra.state())))
        spectra.feed(t[a:b], {n: v[a:b] for n, v in x.items()})
        spectra.receive(spectra.hand_over())  # the tick stage takes the finished windows
        for k in list(spectra.done):
            windows[k] = spectra.summed(spectra.take(k))
            spectra.release(windows[k])  # closed: its buffer serves a later window
    windows[spectra.current.index] = spectra.current
    return windows


def restored(pieces: list[int], save_at: int) -> int:
    """The window open when feed_in saved and restored the state (of the last sample fed)."""
    t, _ = stream()
    return int(-(-t[sum(pieces[:save_at]) - 1] // W_NS))


@pytest.mark.parametrize("b", ["own", "same", "parts", "blip"])
@pytest.mark.parametrize("plain", [False, True], ids=["compiled", "plain"])
def test_window_sums_are_the_same_bits_for_any_split_and_across_a_saved_state(plain, b):
    """Also when the two signals are equal (transformed once) or equal for a while."""
    with uncompiled() if plain else contextlib.nullcontext():
        check_window_sums(b)


def check_window_sums(b: str) -> None:
    t, x = stream(b)
    ref = reference(t, x)
    assert sorted(ref) == [8_334, 8_335, 8_337, 8_338]
    assert [r["segments"] for r in ref.values()] == [5, 4, 2, 1]
    assert [r["dropped"] for r in ref.values()] == [0, 1, 0, 0]
    assert [r["fs"] for r in ref.values()] == [20.0, 20.0, 10.0, 20.0]
    assert [r["open"].size for r in ref.values()] == [880, 840, 952, 976]
    rng = np.random.default_rng(9)
    random = rng.integers(1, 3000, 400)
    splits = {
        "whole": [t.size],
        "one sample then a slab": [1, 2047, 1, 1, *[1000] * (t.size // 1000)],
        "random": random[np.cumsum(random) < t.size].tolist(),
    }
    for name, pieces in splits.items():
        pieces = [*pieces, t.size - sum(pieces)]
        for save_at in (None, len(pieces) // 2):
            got = feed_in(pieces, save_at, b)
            assert sorted(got) == sorted(ref), name
            if name == "random":  # a closed window's buffer was reused by a later one
                assert len({id(g.rows) for g in got.values()}) < len(got)
            shared = {k: g.same == [0, 0] for k, g in got.items()}
            # a restored window counts its signals as different (its state says nothing)
            want = {"own": [False] * 4, "same": [save_at is None or k != restored(pieces, save_at)
                                                  for k in sorted(ref)],
                    "parts": [k == 8_334 and (save_at is None or k != restored(pieces, save_at))
                              for k in sorted(ref)],
                    "blip": [k != 8_335 and (save_at is None or k != restored(pieces, save_at))
                             for k in sorted(ref)]}[b]
            assert [shared[k] for k in sorted(ref)] == want, (name, save_at)
            for k, r in ref.items():
                g = got[k]
                assert (g.segments, g.dropped) == (r["segments"], r["dropped"]), (name, k)
                assert np.array_equal(g.t, r["open"])
                if r["segments"]:
                    assert g.fs == r["fs"]
                    for n in NAMES:
                        assert np.array_equal(g.sums()[n].view(np.int64),
                                              r["psd"][n].view(np.int64)), (name, k, n)


TICK_S = 0.1  # 300 ticks a 30 s window; 0.1 s is inexact, so sums depend on their order
TICK_NS = 100_000_000


def tick_stream(seed: int) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Tick ends on the 0.1 s grid from late in a window, with a gap of two windows and more;
    load samples per tick 0 to 2 (a third of the ticks without any) and none over one
    whole window; each component's committed damage growing tick by tick."""
    rng = np.random.default_rng(seed)
    k = (10**10 // TICK_NS + 137 + np.arange(2400)).astype(np.int64)
    k[1500:] += 700  # the gap
    n = rng.integers(0, 3, k.size)
    n[900:1200] = 0
    damage = {c: np.cumsum(rng.uniform(0, 1e-6, k.size)) for c in NAMES}
    return k * TICK_NS, n, damage


def learner_with(state: dict | None = None):
    from monitor.forecast_config import ForecastConfig  # noqa: PLC0415
    from monitor.sea_state_learner import SeaStateLearner  # noqa: PLC0415
    return SeaStateLearner(ForecastConfig(window_s=30.0), {c: None for c in NAMES}, TICK_S,
                           state=state)


def run_ticks(seed: int, batched: bool) -> tuple[object, int]:
    """The stream in random slabs, a state save and restore after the third; in each slab
    the waves samples, then runs of quiet ticks (:meth:`SeaStateLearner.ticks` when
    ``batched``) between single ticks (:meth:`SeaStateLearner.tick`), as the pipeline's
    batched alert path. Returns the learner and how often a committed dict was asked for."""
    ends, n, damage = tick_stream(seed)
    rng = np.random.default_rng(seed + 1)
    learner, asked = learner_with(), 0

    def committed(q: int) -> dict[str, float]:
        nonlocal asked
        asked += 1
        return {c: float(d[a + q]) for c, d in damage.items()}

    cuts = np.sort(rng.choice(np.arange(1, ends.size), 7, replace=False))
    for i, (a, b) in enumerate(zip([0, *cuts.tolist()], [*cuts.tolist(), ends.size])):
        if i == 3:
            learner = learner_with(json.loads(json.dumps(learner.state())))
        slab_t = ends[a:b]
        wave_t = slab_t[::97] - 1
        learner.waves(wave_t, 1.0 + (wave_t % 7) / 3.0, 6.0 + (wave_t % 5))
        learner.receive(learner.hand_over())
        events = np.sort(rng.choice(b - a, min(5, b - a), replace=False)).tolist()
        j = 0
        for stop in [*events, b - a]:
            if batched:
                learner.ticks(slab_t, committed, n[a:b], j, stop)
            else:
                for q in range(j, stop):
                    learner.tick(int(slab_t[q]), committed(q), int(n[a + q]))
            if stop < b - a:
                learner.tick(int(slab_t[stop]), committed(stop), int(n[a + stop]))
            j = stop + 1
    return learner, asked


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_batched_ticks_are_the_per_tick_learner_to_the_bit(seed):
    ref, asked_ref = run_ticks(seed, batched=False)
    got, asked = run_ticks(seed, batched=True)
    assert json.dumps(got.state(), sort_keys=True) == json.dumps(ref.state(), sort_keys=True)
    assert got.covered_s.hex() == ref.covered_s.hex()
    windows = {w["end_ns"] // TICK_NS: w["status"] for w in ref.history}
    # the first tick is 63 before a window's end (too short), the samples-free stretch
    # leaves the window ending at tick 1500 short, the gap closes the one ending at 1800
    # and skips two
    assert list(windows) == [300, 600, 900, 1200, 1500, 1800, 2700, 3000, 3300]
    assert windows[300] == windows[1500] == "short"
    assert list(windows.values()).count("learned") >= 6
    assert asked_ref == 2400
    assert asked <= 1 + 9 + 8 * 5  # the first tick, the closing ones and the single ones
    # the order of the additions shows: 0.1 added n times is not n * 0.1
    ends, n, _ = tick_stream(seed)
    tail = int(np.count_nonzero(n[ends > ref.window_end - 30 * 10**9]))
    assert ref.covered_s != tail * TICK_S
    assert ref.covered_s == float(np.cumsum(np.full(tail, TICK_S))[-1])


def test_the_sums_of_more_signals_than_a_batch_holds():
    """A saved state sums the kept segments of every signal: with more components than a
    batch of periodograms holds (_BATCH_ROWS) it did range(..., 0) and failed; the sums are
    the bits of the same signals summed a few at a time."""
    from monitor.sea_state_learner import _BATCH_ROWS, _Spectra

    names = [f"c{i}" for i in range(_BATCH_ROWS + 1)]
    t = np.arange(3 * SEGMENT, dtype=np.int64) * 50_000_000  # 20 Hz
    x = np.sin(np.arange(3 * SEGMENT) * 0.3)
    signals = {n: x * (i + 1) for i, n in enumerate(names)}
    many = _Spectra(names)
    many.feed(t, signals)
    sums = many.sums()
    assert sorted(sums) == sorted(names) and many.segments == 3
    few = _Spectra(names[-2:])
    few.feed(t, {n: signals[n] for n in names[-2:]})
    for n, want in few.sums().items():
        assert np.array_equal(sums[n], want) and want.max() > 0


def learner_state(pipeline) -> str:
    return json.dumps(pipeline.state()["sea_states"], allow_nan=True)


def test_the_learner_state_is_the_same_live_and_in_replays_of_any_block_split(tmp_path):
    """A window closed by its tick while its spectra were still the feeding side's open
    window (no load sample after its end yet) was handed over again when the next window's
    first sample came, and stayed in ``done`` until the next window closed: in the state of
    a run of 1-s blocks with the live ordering horizon (as the daemon runs), not in a
    replay's. Minute windows over 130 s of tension (silent from 90 to 120 s, across the
    window end at 100 s) and IMU, written to a log: the learner's state of the live run is
    the replay's, coalesced or block by block; the replays' whole states are equal."""
    from monitor.config import config_with, default_config
    from monitor.pipeline import Pipeline
    from replay.reader import LogReader
    from replay.runner import run_blocks
    from replay.writer import LogWriter
    from synthetic_buoy import S, T0, blocks_interleaved, sea

    config = default_config()
    config = config_with(config, forecast={**config.section("forecast"), "window_s": 60.0})
    log = tmp_path / "gap.mcap"
    with LogWriter(log) as w:
        for block in blocks_interleaved(sea(130, gap=(90, 120)), 1):
            w.write_block(block)
    live = Pipeline(config)  # the daemon's pipeline: live horizon, 1-s blocks
    for block in LogReader([log], coalesce=False):
        live.process(block)
    live.flush()
    replayed, _ = run_blocks(config, LogReader([log]))
    fine, _ = run_blocks(config, LogReader([log], coalesce=False))
    # the windows ending at 40 s and 100 s closed; the one ending at 160 s is open
    for p in (live, replayed, fine):
        assert [(w["end_ns"] - T0) // S for w in p.sea_states.history] == [40, 100]
        assert p.sea_states.window_end == T0 + 160 * S
    assert learner_state(live) == learner_state(replayed) == learner_state(fine)
    assert json.dumps(replayed.state(), allow_nan=True) == json.dumps(fine.state(),
                                                                      allow_nan=True)
    # a state saved before (a closed window kept in "done") loads, and forgets that window
    # at the next slab: the run continued from it ends with the same state
    cut = next(i for i, b in enumerate(LogReader([log], coalesce=False))
               if b.t_first_ns >= T0 + 125 * S)
    blocks = list(LogReader([log], coalesce=False))
    first = Pipeline(config)
    for block in blocks[:cut]:
        first.process(block)
    old = json.loads(json.dumps(first.state(), allow_nan=True))
    stress = old["sea_states"]["stress"]
    closed = stress["current"]["index"] - 1
    stress["done"][str(closed)] = {**stress["current"], "index": closed}
    second = Pipeline(config, state=old)
    assert closed in second.sea_states.stress.done
    for block in blocks[cut:]:
        second.process(block)
    second.flush()
    assert learner_state(second) == learner_state(live)
