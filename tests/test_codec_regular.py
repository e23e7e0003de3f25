"""The one-pass decoder of regular payloads gives what the general kernel gives, bit for bit,
and declines every payload it does not fully understand."""

from __future__ import annotations

import numpy as np

from monitor import codec
from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor.codec_regular import decode_regular
from tests.byte_mutations import mutated

T0 = 1_700_000_000_123_456_789


def _payload(sensor: str, n: int, seed: int, *, period: int = 50_000_000,
             nan_at: int | None = None) -> bytes:
    rng = np.random.default_rng(seed)
    t = T0 + period * np.arange(n, dtype=np.int64)
    fields = {f: 5000.0 * rng.normal(size=n) for f in SENSOR_FIELDS[sensor]}
    if nan_at is not None:
        fields[next(iter(SENSOR_FIELDS[sensor]))][nan_at] = np.nan
    return codec.encode_block(SampleBlock("b", sensor, t, fields))


def _batch(payloads: list[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    buf = np.frombuffer(b"".join(payloads), np.uint8)
    lens = np.array([len(p) for p in payloads], np.int64)
    return buf, np.cumsum(lens) - lens, lens


def _general(buf, offs, lens, numbers):
    fn_t0, fn_period, fn_off, fn_vals, sub = numbers
    return codec._decode_kernel(buf, offs, lens, fn_t0, fn_period, fn_off,
                                np.asarray(fn_vals, np.int64), np.asarray(sub, np.int64))


def _same(a: tuple, b: tuple) -> bool:
    return all(x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()
               for x, y in zip(a, b))


def test_regular_batches_decode_in_one_pass_to_the_same_bits():
    for sensor in ("tension", "imu"):
        numbers = codec.DEFAULT_FIELD_NUMBERS[sensor]
        payloads = [_payload(sensor, n, seed) for seed, n in enumerate((20, 2, 37, 20, 400))]
        buf, offs, lens = _batch(payloads)
        fast = decode_regular(buf, offs, lens, numbers)
        assert fast is not None
        assert fast[1].tolist() == [20, 2, 37, 20, 400]
        assert fast[3].flags.c_contiguous and fast[3].shape == (len(SENSOR_FIELDS[sensor]), 479)
        assert _same(fast, _general(buf, offs, lens, numbers))
        assert _same(codec.decode_many(buf, offs, lens, numbers), fast)


def test_other_shapes_are_left_to_the_general_kernel():
    numbers = codec.DEFAULT_FIELD_NUMBERS["tension"]
    irregular = codec.encode_block(SampleBlock(
        "b", "tension", np.array([T0, T0 + 3, T0 + 10], np.int64),
        {"tension_N": np.array([1.0, 2.0, 3.0])}))
    for odd in (_payload("tension", 20, 1, nan_at=4),  # a raw sample
                _payload("tension", 1, 2),  # one sample: no period
                irregular,  # time offsets
                _payload("tension", 20, 3)[:-1]):  # cut
        buf, offs, lens = _batch([_payload("tension", 20, 0), odd])
        assert decode_regular(buf, offs, lens, numbers) is None
        assert _same(codec.decode_many(buf, offs, lens, numbers),
                     _general(buf, offs, lens, numbers))
    # the float64 format (v1) has no quantized fields
    buf, offs, lens = _batch([_payload("tension", 20, 0)])
    assert decode_regular(buf, offs, lens, (1, 2, 3, (4,), codec.DOUBLES)) is None


def test_mutated_payloads_the_fast_path_accepts_decode_as_the_general_kernel_does():
    """3000 random byte edits of regular payloads: whatever the one-pass decoder accepts, the
    general kernel decodes to the same status, counts, times and value bits."""
    rng = np.random.default_rng(11)
    base = {s: _payload(s, 20 if s == "tension" else 10, 5) for s in ("tension", "imu")}
    accepted = 0
    for k in range(3000):
        sensor = ("tension", "imu")[k % 2]
        b = mutated(base[sensor], rng, k)
        numbers = codec.DEFAULT_FIELD_NUMBERS[sensor]
        buf, offs, lens = _batch([base[sensor], b])
        fast = decode_regular(buf, offs, lens, numbers)
        if fast is not None:
            accepted += 1
            assert _same(fast, _general(buf, offs, lens, numbers))
    # value bytes edited in place stay regular: many mutants take the fast path
    assert 300 < accepted < 2500
