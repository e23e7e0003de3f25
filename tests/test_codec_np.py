"""The numpy-only encoder (monitor.codec_np, used by the bridge and custom drivers) gives the
same bytes as the numba kernel of monitor.codec: on the Maine load cell as the bridge reads
it, and on values that are hard to quantize or cannot be (ties, NaN, infinities, huge)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monitor import codec, codec_np
from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor.quanta import quanta

REPO = Path(__file__).resolve().parents[1]
SHARED = next((p / "shared" / "realdata" for p in REPO.parents
               if (p / "shared" / "realdata").is_dir()), REPO.parent / "shared" / "realdata")
MAINE = SHARED / "maine_endline_loadcell" / "17348481-2018.11.30-09.58.27-15.csv"
T0 = 1_700_000_000_123_456_789
LBF = 4.4482216


@pytest.mark.skipif(not MAINE.exists(), reason="shared/realdata not beside the project")
@pytest.mark.parametrize("q", [0.1, 1e-3, 4.0])
def test_maine_load_cell_blocks_are_byte_identical(q):
    """17,228 measured samples (load in lbf -> N, the logger's irregular ~3 Hz times, and
    the elapsed-time column as a second field), cut into blocks of 1 to 500 samples."""
    rows = [r.split(",") for r in MAINE.read_text().splitlines()]
    t = np.array([np.datetime64(r[0][:10] + "T" + r[0][11:], "ns").astype(np.int64)
                  for r in rows])
    vals = np.array([[float(r[1]) for r in rows], [float(r[3]) * LBF for r in rows]])
    assert t.shape[0] > 17_000 and np.any(np.diff(t) != np.diff(t)[0])  # irregular
    rng = np.random.default_rng(2)
    a, n_blocks = 0, 0
    while a < t.shape[0]:
        b = min(t.shape[0], a + int(rng.integers(1, 500)))
        qs = np.array([q, q])
        ref = codec.encode_samples(t[a:b], vals[:, a:b], qs)
        assert codec_np.encode_samples(t[a:b], vals[:, a:b], qs) == ref
        a, n_blocks = b, n_blocks + 1
    assert n_blocks > 60
    # the regular time base (period_ns) too: the same samples at 1 kHz
    reg = T0 + np.arange(t.shape[0], dtype=np.int64) * 1_000_000
    assert (codec_np.encode_samples(reg, vals, np.array([q, q]))
            == codec.encode_samples(reg, vals, np.array([q, q])))


def _hard_values(q: float, rng: np.random.Generator) -> np.ndarray:
    k = rng.integers(-10**6, 10**6, 200)
    return np.concatenate([
        rng.normal(0, 1e4 * q, 200),                     # ordinary
        (k + 0.5) * q, (k + 0.5) * q * (1 + 1e-15),      # ties, and one ulp beside them
        rng.normal(0, 1e30, 20), rng.uniform(-1, 1, 20) * 1e308,  # huge: kept raw
        np.array([0.0, -0.0, 5e-324, q / 2, -q / 2, 2.0 ** 52 * q, 2.0 ** 53 * q,
                  np.nextafter(2.0 ** 52, 0) * q, 1e300, -1e300, np.inf, -np.inf, np.nan,
                  -np.nan]),
        (np.array([np.nan]).view(np.int64) + 7).view(np.float64),  # a NaN with a payload
        rng.integers(-2**62, 2**62, 30).astype(np.float64) * q,  # deltas of many bytes
    ])


@pytest.mark.parametrize("q", [0.1, 1e-4, 1e-7, 3.0, 2.0 ** -20])
def test_hard_values_and_every_time_base_are_byte_identical(q):
    rng = np.random.default_rng(int(q * 1e7) % 1000)
    v = _hard_values(q, rng)
    rng.shuffle(v)
    n = v.shape[0]
    assert np.count_nonzero(~np.isfinite(v)) >= 5
    bases = {"regular": T0 + np.arange(n, dtype=np.int64) * 7,
             "irregular": T0 + np.cumsum(rng.integers(1, 10**9, n)),
             "backwards": T0 + rng.integers(-10**12, 10**12, n),  # offsets of either sign
             "equal": np.full(n, T0, np.int64)}
    for name, t in bases.items():
        for a, b in ((0, n), (0, 1), (5, 7), (17, n - 3)):
            two = np.stack([v[a:b], v[::-1][a:b]])
            ref = codec.encode_samples(t[a:b], two, np.array([q, 2 * q]))
            assert codec_np.encode_samples(t[a:b], two, np.array([q, 2 * q])) == ref, (name, a, b)
    # what the numba path keeps raw, the numpy path does too (the test is not vacuous)
    payload = codec_np.encode_samples(bases["regular"], v[None], np.array([q]))
    dec = codec.decode_block("b", "tension", payload).fields["tension_N"]
    with np.errstate(over="ignore", invalid="ignore"):
        raw = ~(np.abs(v / q) < 2.0 ** 52)
    assert v[raw].view(np.int64).tolist() == dec[raw].view(np.int64).tolist()
    assert np.all(np.abs(dec[~raw] - v[~raw]) <= q / 2)


@pytest.mark.parametrize("sensor", sorted(SENSOR_FIELDS))
def test_blocks_of_every_stream_with_overridden_quanta(sensor):
    rng = np.random.default_rng(9)
    t = T0 + np.cumsum(rng.integers(1, 10**8, 300))
    blk = SampleBlock("b", sensor, t, {f: rng.normal(0, 100, 300) for f in SENSOR_FIELDS[sensor]})
    over = {next(iter(SENSOR_FIELDS[sensor])): 0.5}
    assert codec_np.encode_block(blk, over) == codec.encode_block(blk, over)
    assert codec_np.encode_block(blk) == codec.encode_block(blk)
    assert quanta(sensor, over)[0] == 0.5
    with pytest.raises(ValueError, match="empty block"):
        codec_np.encode_block(SampleBlock("b", sensor, t[:0], {f: np.zeros(0) for f in
                                                               SENSOR_FIELDS[sensor]}))


def test_varints_of_every_length():
    z = np.array([0, 1, 127, 128, 300, 16383, 16384, 2**32, 2**63 - 1, 2**63, 2**64 - 1],
                 np.uint64)
    assert codec_np.varints(z).tobytes() == b"".join(codec_np.varint(int(x)) for x in z)
    assert codec_np.varint(300) == b"\xac\x02" and codec_np.varint(2**64 - 1)[-1] == 1
    assert len(codec_np.varint(2**64 - 1)) == 10 and codec_np.varints(z[:0]).shape == (0,)
