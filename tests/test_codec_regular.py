"""The one-pass decoder of regular payloads gives what the general kernel gives, bit for bit,
and declines every payload it does not fully understand."""

from __future__ import annotations

import contextlib

import numpy as np

from models._jit import uncompiled
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
                                np.asarray(fn_vals, np.int64), np.asarray(sub, np.int64), 0)


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


def _generic_class(sensor: str):
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(codec.file_descriptor_set(sensor)).file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(codec.schema_name(sensor)))


# sint64 deltas by varint length: 1, 2, 3 bytes, up to 9 (the one-pass decoder's limit), and
# the extremes, whose zigzag needs 10 bytes (left to the general kernel)
_DELTA_RANGES = ((-64, 63), (-8192, 8191), (-2**20, 2**20 - 1), (-2**62, 2**62 - 1))
_EXTREMES = (-2**63, 2**63 - 1, -2**62 - 1, 2**62)


def test_random_payloads_of_the_reference_encoder_decode_as_protobuf_reads_them():
    """Payloads serialized by the protobuf runtime from random messages (varints of every
    length, overflowing sums, tiny and huge quanta): the decoder's times and values are the
    reference decode's (protobuf parse, then docs/LOG_FORMAT.md's recipe) to the last bit,
    and the one-pass path takes every batch without a 10-byte varint."""
    rng = np.random.default_rng(2026)
    fast_batches = 0
    for trial in range(60):
        sensor = ("tension", "imu")[trial % 2]
        cls, names = _generic_class(sensor), SENSOR_FIELDS[sensor]
        extreme = trial % 5 == 4
        payloads, want_t, want_v = [], [], []
        for _ in range(int(rng.integers(1, 7))):
            n = int(rng.integers(2, 80))
            m = cls(t0_ns=int(rng.integers(1, 2**62)), period_ns=int(rng.integers(1, 2**40)))
            for f in names:
                lo, hi = _DELTA_RANGES[int(rng.integers(0, 4))] if trial % 3 else (-64, 8191)
                d = rng.integers(lo, hi, n, endpoint=True)
                if extreme:
                    d[rng.integers(0, n)] = rng.choice(_EXTREMES)
                q = getattr(m, f)
                q.quantum = float(rng.choice([0.1, 1e-4, 3.0, 5e-324, 1e300]))
                q.delta.extend(d.tolist())
            payloads.append(m.SerializeToString())
            ref = cls.FromString(payloads[-1])
            with np.errstate(over="ignore"):
                want_t.append(ref.t0_ns + ref.period_ns * np.arange(n, dtype=np.int64))
                want_v.append([np.cumsum(np.array(getattr(ref, f).delta, np.int64))
                               .astype(np.float64) * getattr(ref, f).quantum for f in names])
        buf, offs, lens = _batch(payloads)
        numbers = codec.DEFAULT_FIELD_NUMBERS[sensor]
        status, nsamp, t, vals = codec.decode_many(buf, offs, lens, numbers)
        assert (status == codec.OK).all()
        assert nsamp.tolist() == [w.shape[0] for w in want_t]
        assert t.tolist() == np.concatenate(want_t).tolist()
        want = np.concatenate([np.array(v) for v in want_v], axis=1)
        assert vals.shape == want.shape and vals.tobytes() == want.tobytes()
        fast = decode_regular(buf, offs, lens, numbers)
        assert (fast is None) == extreme
        if fast is not None:
            fast_batches += 1
            assert fast[3].flags.c_contiguous
            assert _same(fast, (status, nsamp, t, vals))
        if trial < 5:  # the kernel as plain Python (small jobs run it so) gives the same
            with uncompiled():
                plain = decode_regular(buf, offs, lens, numbers)
            assert (plain is None) == extreme and (extreme or _same(plain, fast))
    assert fast_batches == 48


def test_lengths_whose_varint_starts_with_0x80_take_the_one_pass_path():
    """A field body or delta list of exactly 128 or 256 bytes (its length's first varint
    byte 0x80, the one-byte length read in place must not take it): the one-pass decoder
    takes the payloads and gives the reference decode's values."""
    cls = _generic_class("tension")
    payloads, want = [], []
    for n in (128, 244):  # one-byte deltas: delta lists of 128 and 244 bytes, bodies 140, 256
        m = cls(t0_ns=T0, period_ns=50_000_000)
        d = np.random.default_rng(n).integers(-64, 63, n, endpoint=True)
        m.tension_N.quantum = 0.1
        m.tension_N.delta.extend(d.tolist())
        payloads.append(m.SerializeToString())
        want.append(np.cumsum(d).astype(np.float64) * 0.1)
    assert bytes([0x80, 0x01]) in payloads[0] and bytes([0x80, 0x02]) in payloads[1]
    buf, offs, lens = _batch(payloads)
    fast = decode_regular(buf, offs, lens, codec.DEFAULT_FIELD_NUMBERS["tension"])
    assert fast is not None and fast[1].tolist() == [128, 244]
    assert fast[3].tobytes() == np.concatenate(want)[None].tobytes()


def test_room_in_front_leaves_the_decoded_samples_as_they_are():
    """``front`` unset samples before the decoded ones, on the one-pass path (one field: a
    view of a larger array; several: sized exactly) and the general kernel's (a raw sample),
    compiled and as plain Python: behind them, the bits of a decode without room."""
    for sensor, nan_at in (("tension", None), ("imu", None), ("imu", 3)):
        numbers = codec.DEFAULT_FIELD_NUMBERS[sensor]
        buf, offs, lens = _batch([_payload(sensor, n, seed, nan_at=nan_at if seed == 1 else None)
                                  for seed, n in enumerate((20, 7, 33))])
        plain = codec.decode_many(buf, offs, lens, numbers)
        assert plain[2].shape == (60,) and plain[3].shape[1] == 60
        for front in (1, 1200):
            for mode in (contextlib.nullcontext, uncompiled):
                with mode():
                    status, nsamp, t, vals = codec.decode_many(buf, offs, lens, numbers, front)
                assert vals.flags.c_contiguous and vals.shape[1] == t.shape[0] == front + 60
                assert _same((status, nsamp, t[front:], vals[:, front:]), plain)


def test_several_fields_sized_exactly_whatever_the_payloads_counts():
    """IMU payloads are decoded into exactly sized values (room guessed from the first
    payload's count, counted when a later one has more, copied when fewer): every mix gives
    the general kernel's bits, C-contiguous."""
    numbers = codec.DEFAULT_FIELD_NUMBERS["imu"]
    for counts in ((10, 10, 10), (10, 12, 10), (10, 4, 9), (3, 30), (2,)):
        buf, offs, lens = _batch([_payload("imu", n, s) for s, n in enumerate(counts)])
        fast = decode_regular(buf, offs, lens, numbers)
        assert fast is not None and fast[1].tolist() == list(counts)
        assert fast[3].flags.c_contiguous and fast[3].shape == (3, sum(counts))
        assert _same(fast, _general(buf, offs, lens, numbers))
