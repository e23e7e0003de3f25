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


def stream() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Two stresses (a 0.1 Hz swell and noise) over five-minute windows: the first whole at
    20 Hz (five segments and 880 samples left open at its end); the second with a 2 s gap
    in its second segment (whose rate is then 4 % off: dropped); none in the third; the
    fourth at 10 Hz (its own rate: kept); the fifth with one 20 Hz segment and some
    samples more."""
    rng = np.random.default_rng(5)
    t0 = 8_333 * W_NS

    def at(start_s: float, stop_s: float, dt_s: float) -> np.ndarray:
        n = round((stop_s - start_s) / dt_s)
        return t0 + round(start_s * 1e9) + np.arange(1, n + 1, dtype=np.int64) * round(dt_s * 1e9)

    t = np.concatenate([at(0, 300, 0.05), at(300, 360, 0.05), at(362, 600, 0.05),
                        at(900, 1200, 0.1), at(1200, 1300, 0.05)])
    swell = np.sin(2 * np.pi * 0.1 * (t - t0) / 1e9)
    return t, {"a": 3e6 * swell + 2e5 * rng.normal(size=t.size) + 1e7,
               "b": 1e6 * swell + 5e4 * rng.normal(size=t.size)}


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


def feed_in(pieces: list[int], save_at: int | None = None) -> dict[int, object]:
    t, x = stream()
    spectra = _WindowSpectra(NAMES, W_NS)
    windows = {}
    bounds = np.cumsum([0, *pieces])
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        if i == save_at:
            spectra = _WindowSpectra(NAMES, W_NS, json.loads(json.dumps(spectra.state())))
        spectra.feed(t[a:b], {n: v[a:b] for n, v in x.items()})
        spectra.receive(spectra.hand_over())  # the tick stage takes the finished windows
        for k in list(spectra.done):
            windows[k] = spectra.take(k)
    windows[spectra.current.index] = spectra.current
    return windows


@pytest.mark.parametrize("plain", [False, True], ids=["compiled", "plain"])
def test_window_sums_are_the_same_bits_for_any_split_and_across_a_saved_state(plain):
    with uncompiled() if plain else contextlib.nullcontext():
        check_window_sums()


def check_window_sums() -> None:
    t, x = stream()
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
            got = feed_in(pieces, save_at)
            assert sorted(got) == sorted(ref), name
            for k, r in ref.items():
                g = got[k]
                assert (g.segments, g.dropped) == (r["segments"], r["dropped"]), (name, k)
                assert np.array_equal(g.t, r["open"])
                if r["segments"]:
                    assert g.fs == r["fs"]
                    for n in NAMES:
                        assert np.array_equal(g.psd[n].view(np.int64),
                                              r["psd"][n].view(np.int64)), (name, k, n)
