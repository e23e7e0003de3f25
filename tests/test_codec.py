"""Block payload codec: exact bytes, the half-quantum bound, round trips, the v1 format, and
decoding by generic protobuf tooling."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor import codec
from monitor.quanta import DEFAULT_QUANTA, parse_quanta, quanta
from tests.byte_mutations import mutated

T0 = 1_700_000_000_123_456_789
V1_NUMBERS = (1, 2, 3, (4,), codec.DOUBLES)  # the v1 tension schema: packed doubles


def _block(sensor: str, t: np.ndarray, seed: int = 0, scale: float = 1.0) -> SampleBlock:
    rng = np.random.default_rng(seed)
    return SampleBlock("b-1", sensor, t.astype(np.int64),
                       {f: scale * rng.normal(size=t.shape[0]) for f in SENSOR_FIELDS[sensor]})


def _generic_class(sensor: str):
    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(codec.file_descriptor_set(sensor)).file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(codec.schema_name(sensor)))


def _generic_values(q) -> np.ndarray:
    """docs/LOG_FORMAT.md's recipe on a generically decoded Quantized message."""
    v = np.cumsum(np.array(q.delta, np.int64)).astype(np.float64) * q.quantum
    v[np.array(q.raw_index, np.int64)] = np.array(q.raw_value)
    return v


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.view(np.int64).tolist() == b.view(np.int64).tolist()


def _check_within_half_quantum(original: np.ndarray, decoded: np.ndarray, q: float) -> None:
    """The format's promise: every finite sample within q/2; anything else bit for bit."""
    finite = np.isfinite(original) & np.isfinite(decoded)
    assert np.all(np.abs(decoded[finite] - original[finite]) <= q / 2)
    kept = ~finite
    assert _same_bits(original[kept], decoded[kept])


def test_exact_bytes_of_a_regular_tension_block():
    t = np.array([T0, T0 + 50_000_000], np.int64)
    blk = SampleBlock("b", "tension", t, {"tension_N": np.array([1000.5, -2.3])})
    payload = codec.encode_block(blk)
    # 1000.5 N = 10005 quanta of 0.1 N, -2.3 N = -23: deltas 10005, -10028 -> zigzag 20010,
    # 20055 -> varints AA 9C 01, D7 9C 01; Quantized = quantum (09 + 8 bytes), delta (12 06 ...)
    quantized = b"\x09" + struct.pack("<d", 0.1) + b"\x12\x06\xaa\x9c\x01\xd7\x9c\x01"
    expected = (b"\x09" + struct.pack("<q", T0) + b"\x10\x80\xe1\xeb\x17"
                + b"\x22" + bytes((len(quantized),)) + quantized)
    assert payload == expected
    # the generic runtime serializes the same message to the same bytes
    cls = _generic_class("tension")
    m = cls(t0_ns=T0, period_ns=50_000_000)
    m.tension_N.quantum = 0.1
    m.tension_N.delta.extend([10005, -10028])
    assert m.SerializeToString() == expected
    dec = codec.decode_block("b", "tension", payload).fields["tension_N"]
    assert dec.tolist() == [10005 * 0.1, -23 * 0.1]


def test_irregular_times_use_zigzag_offsets():
    t = np.array([T0, T0 + 3, T0 - 1], np.int64)  # offsets 0, 3, -1 -> zigzag 0, 6, 1
    blk = SampleBlock("b", "tension", t, {"tension_N": np.zeros(3)})
    payload = codec.encode_block(blk)
    assert payload[9:14] == b"\x1a\x03\x00\x06\x01"
    assert codec.decode_block("b", "tension", payload).t_ns.tolist() == t.tolist()


@pytest.mark.parametrize("sensor", sorted(SENSOR_FIELDS))
@pytest.mark.parametrize("kind", ["regular", "irregular", "single"])
def test_round_trip_within_half_a_quantum_and_generic_protobuf_agrees(sensor, kind):
    rng = np.random.default_rng(3)
    if kind == "regular":
        t = T0 + np.arange(37) * 100_000_000
    elif kind == "irregular":
        t = T0 + np.cumsum(rng.integers(1, 10**9, 25))
    else:
        t = np.array([T0])
    blk = _block(sensor, np.asarray(t, np.int64), scale=50.0)
    payload = codec.encode_block(blk)
    dec = codec.decode_block("b-1", sensor, payload)
    assert np.array_equal(dec.t_ns, blk.t_ns)
    m = _generic_class(sensor).FromString(payload)
    n = len(blk)
    times = (m.t0_ns + np.array(m.t_offset_ns, np.int64) if len(m.t_offset_ns)
             else m.t0_ns + m.period_ns * np.arange(n))
    assert np.array_equal(times, blk.t_ns)
    for f in SENSOR_FIELDS[sensor]:
        q = DEFAULT_QUANTA[f]
        assert getattr(m, f).quantum == q
        _check_within_half_quantum(blk.fields[f], dec.fields[f], q)
        assert _same_bits(_generic_values(getattr(m, f)), dec.fields[f])
        # decoded values are on the grid: encoding them again loses nothing
        assert not np.array_equal(dec.fields[f], blk.fields[f])
    again = codec.decode_block("b-1", sensor, codec.encode_block(dec))
    assert all(_same_bits(again.fields[f], dec.fields[f]) for f in SENSOR_FIELDS[sensor])
    # and what the generic runtime serializes, our decoder reads
    back = codec.decode_block("b-1", sensor, m.SerializeToString())
    assert all(_same_bits(back.fields[f], dec.fields[f]) for f in SENSOR_FIELDS[sensor])


@pytest.mark.parametrize("q", [0.1, 1e-4, 1e-7, 3.0, 2.0 ** -20])
def test_half_quantum_bound_holds_for_hard_values(q):
    rng = np.random.default_rng(11)
    k = rng.integers(-10**6, 10**6, 200)
    v = np.concatenate([
        rng.normal(0, 1e4 * q, 200),            # ordinary
        (k + 0.5) * q,                           # exact ties
        (k + 0.5) * q * (1 + 1e-15),            # one ulp around the ties
        np.array([0.0, -0.0, 5e-324, q / 2, -q / 2, 2.0 ** 52 * q, 2.0 ** 53 * q, 1e300,
                  -1e300, np.inf, -np.inf, np.nan, np.float64(np.nan) * -1]),
    ])
    t = T0 + np.arange(v.shape[0], dtype=np.int64)
    payload = codec.encode_samples(t, v[None], np.array([q]))
    dec = codec.decode_block("b", "tension", payload).fields["tension_N"]
    m = _generic_class("tension").FromString(payload)
    assert m.tension_N.quantum == q
    _check_within_half_quantum(v, dec, q)
    assert _same_bits(_generic_values(m.tension_N), dec)
    # what cannot be stored as quanta is kept raw, with a zero delta: non-finite, too large,
    # and exact ties where float rounding puts both neighbours a hair beyond q / 2; never an
    # ordinary value
    raw = np.array(m.tension_N.raw_index)
    assert {np.inf, -np.inf, 1e300, -1e300, 2.0 ** 53 * q} <= set(v[raw].tolist())
    assert raw.min() >= 200 and np.count_nonzero(raw >= 600) == 8
    assert all(np.array(m.tension_N.delta)[raw] == 0)


def test_numba_bulk_encoder_matches_the_block_encoder():
    rng = np.random.default_rng(5)
    t = np.concatenate([T0 + np.arange(10) * 10**8,
                        T0 + 10**9 + np.cumsum(rng.integers(1, 10**7, 7))])
    vals = rng.normal(size=(3, t.shape[0]))
    vals[1, 4] = np.nan
    q = quanta("imu")
    out = np.zeros(codec.payload_bound(t.shape[0], 3), np.uint8)
    for a, b in ((0, 10), (10, 17), (3, 4), (2, 12)):
        end = codec.put_payload(out, 0, t, vals, q, a, b)
        blk = SampleBlock("b", "imu", t[a:b].copy(),
                          {f: vals[i, a:b].copy() for i, f in enumerate(SENSOR_FIELDS["imu"])})
        assert out[:end].tobytes() == codec.encode_block(blk)
        assert end <= codec.payload_bound(b - a, 3)


def test_quanta_defaults_overrides_and_errors():
    assert quanta("tension").tolist() == [0.1]
    assert quanta("imu", {"accel_y_mps2": 0.01, "tension_N": 1.0}).tolist() == [
        1e-4, 0.01, 1e-4]
    assert parse_quanta(["tension_N=0.01", "lat_deg=1e-8"]) == {
        "tension_N": 0.01, "lat_deg": 1e-8}
    for bad in (["tension_N"], ["tension=0.1"], ["tension_N=0"], ["tension_N=-1"],
                ["tension_N=nan"], ["tension_N=x"], ["tension_N=inf"]):
        with pytest.raises(ValueError, match="--quantum"):
            parse_quanta(bad)
    with pytest.raises(ValueError, match="unknown fields"):
        quanta("tension", {"tension": 0.1})
    with pytest.raises(ValueError, match="finite and > 0"):
        quanta("tension", {"tension_N": 0.0})
    coarse = SampleBlock("b", "tension", np.array([T0]), {"tension_N": np.array([12.34])})
    dec = codec.decode_block("b", "tension", codec.encode_block(coarse, {"tension_N": 5.0}))
    assert dec.fields["tension_N"].tolist() == [10.0]


def test_unpacked_fields_unknown_fields_and_any_order_decode():
    # Quantized with the deltas unpacked (one varint field each), the quantum last, and an
    # unknown field; the block with the values before t0 and an unknown field
    quantized = (b"\x10\x14" + b"\x10\x03" + b"\x78\x2a" + b"\x09" + struct.pack("<d", 0.5))
    payload = (b"\x78\x2a" + b"\x22" + bytes((len(quantized),)) + quantized
               + b"\x09" + struct.pack("<q", T0) + b"\x10\x05")
    blk = codec.decode_block("b", "tension", payload)
    # zigzag 20 -> 10, 3 -> -2: quanta 10, 8 -> 5.0, 4.0
    assert blk.t_ns.tolist() == [T0, T0 + 5] and blk.fields["tension_N"].tolist() == [5.0, 4.0]
    m = _generic_class("tension")()
    assert m.ParseFromString(payload) == len(payload)
    assert _generic_values(m.tension_N).tolist() == [5.0, 4.0]


def test_raw_samples_decode_whatever_the_field_order():
    """raw_value before raw_index, an unpacked raw value: the same samples."""
    nan, big = struct.pack("<d", np.nan), struct.pack("<d", 1e300)
    for quantized in (
            b"\x09" + struct.pack("<d", 0.5) + b"\x12\x03\x02\x00\x00"
            + b"\x1a\x02\x01\x02" + b"\x22\x10" + nan + big,
            b"\x22\x10" + nan + big + b"\x1a\x02\x01\x02" + b"\x12\x03\x02\x00\x00"
            + b"\x09" + struct.pack("<d", 0.5),
            b"\x21" + nan + b"\x1a\x02\x01\x02" + b"\x21" + big
            + b"\x12\x03\x02\x00\x00" + b"\x09" + struct.pack("<d", 0.5)):
        v = codec.decode_block("b", "tension", _tension(quantized)).fields["tension_N"]
        assert v[0] == 0.5 and np.isnan(v[1]) and v[2] == 1e300


def _tension(quantized: bytes, head: bytes = b"\x09" + struct.pack("<q", T0) + b"\x10\x05"):
    return head + b"\x22" + bytes((len(quantized),)) + quantized


_Q = b"\x09" + struct.pack("<d", 0.1)


@pytest.mark.parametrize("payload, reason", [
    (_tension(_Q + b"\x12\x02\x02\x04")[:-1], "malformed"),  # cut short
    (_tension(_Q + b"\x12\x02\x02\x04", head=b"\x09" + struct.pack("<q", T0)), "no period_ns"),
    (_tension(_Q + b"\x12\x01\x02", head=b"\x10\x05"), "t0_ns missing"),
    (_tension(_Q + b"\x12\x02\x02\x84"), "malformed"),  # a varint cut inside the packed run
    (_tension(_Q + b"\x12\x02\x02\x04", head=b"\x09" + struct.pack("<q", T0) + b"\x1a\x01\x00"),
     "disagree"),
    (_tension(b"\x12\x02\x02\x04"), "quantum missing"),
    (_tension(b"\x09" + struct.pack("<d", 0.0) + b"\x12\x01\x02"), "quantum"),
    (_tension(b"\x09" + struct.pack("<d", np.nan) + b"\x12\x01\x02"), "quantum"),
    (_tension(b"\x09" + struct.pack("<d", -0.1) + b"\x12\x01\x02"), "quantum"),
    (_tension(_Q + b"\x12\x02\x02\x04\x1a\x01\x01"), "disagree"),  # raw index, no raw value
    (_tension(_Q + b"\x12\x02\x02\x04\x1a\x01\x02\x22\x08" + bytes(8)), "disagree"),  # index 2
    (_tension(_Q + b"\x12\x01\x02") + b"\x22\x0c" + _Q + b"\x12\x01\x02", "appears twice"),
])
def test_malformed_payloads_raise_value_error(payload, reason):
    with pytest.raises(ValueError, match=reason):
        codec.decode_block("b", "tension", payload)


def test_v1_payloads_of_packed_doubles_still_decode():
    """The first format (``repeated double`` values): decoded when the schema says so."""
    v1 = (b"\x09" + struct.pack("<q", T0) + b"\x10\x80\xe1\xeb\x17"
          + b"\x22\x10" + struct.pack("<2d", 1000.5, -2.25))
    blk = codec.decode_block("b", "tension", v1, numbers=V1_NUMBERS)
    assert blk.t_ns.tolist() == [T0, T0 + 50_000_000]
    assert blk.fields["tension_N"].tolist() == [1000.5, -2.25]
    unpacked = b"\x21" + struct.pack("<d", 1.0) + b"\x21" + struct.pack("<d", 2.0)
    blk = codec.decode_block("b", "tension", unpacked + b"\x09" + struct.pack("<q", T0)
                             + b"\x10\x05", numbers=V1_NUMBERS)
    assert blk.fields["tension_N"].tolist() == [1.0, 2.0]
    with pytest.raises(ValueError, match="malformed"):  # 7 bytes are no double
        codec.decode_block("b", "tension", b"\x09" + struct.pack("<q", T0) + b"\x10\x05\x22\x07"
                           + bytes(7), numbers=V1_NUMBERS)


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="unknown sensor 'sonar'"):
        codec.file_descriptor_set("sonar")
    empty = SampleBlock("b", "tension", np.empty(0, np.int64), {"tension_N": np.empty(0)})
    with pytest.raises(ValueError, match="empty block"):
        codec.encode_block(empty)


def test_field_numbers_and_value_encoding_are_read_from_the_stored_schema():
    fds = descriptor_pb2.FileDescriptorSet.FromString(codec.file_descriptor_set("gnss"))
    for fld in fds.file[-1].message_type[0].field:
        if fld.name == "lon_deg":
            fld.number = 9
    for fld in fds.file[0].message_type[0].field:
        if fld.name == "delta":
            fld.number = 7
    name = "buoymon.v2.GnssBlock"
    numbers = codec.field_numbers_from_schema(fds.SerializeToString(), name, "gnss")
    assert numbers == (1, 2, 3, (4, 9), (1, 7, 3, 4))
    with pytest.raises(ValueError, match="missing fields"):
        codec.field_numbers_from_schema(codec.file_descriptor_set("gnss"), name, "imu")
    # a v1 schema: the same message with double values
    for fld in fds.file[-1].message_type[0].field:
        if fld.type == fld.TYPE_MESSAGE:
            fld.type, fld.type_name = fld.TYPE_DOUBLE, ""
            fld.label = fld.LABEL_REPEATED
    assert codec.field_numbers_from_schema(fds.SerializeToString(), name, "gnss") == (
        1, 2, 3, (4, 9), codec.DOUBLES)
    fds.file[-1].message_type[0].field[3].type = descriptor_pb2.FieldDescriptorProto.TYPE_FLOAT
    with pytest.raises(ValueError, match="all be double or all Quantized"):
        codec.field_numbers_from_schema(fds.SerializeToString(), name, "gnss")


def test_shipped_proto_file_matches_the_runtime_schemas():
    from pathlib import Path

    shipped = Path(codec.__file__).with_name("buoymon.proto").read_text()
    assert shipped == codec.proto_text()
    assert "  Quantized accel_z_mps2 = 6;  // m/s^2" in shipped
    assert "  repeated sint64 delta = 2;  // quanta" in shipped
    assert "  sfixed64 t0_ns = 1;  // ns" in shipped


def test_mutated_payloads_decode_consistently_or_raise_value_error():
    """3000 random byte edits of valid payloads (NaN and irregular times included): the
    decoder, which has no bounds checks of its own, validates before it writes; every result
    is a ValueError or a block whose fields all have one value per time."""
    rng = np.random.default_rng(7)
    payloads = []
    for sensor, t in (("tension", T0 + np.arange(20) * 10**8),
                      ("imu", T0 + np.cumsum(rng.integers(1, 10**8, 9)))):
        blk = _block(sensor, np.asarray(t, np.int64), scale=100.0)
        blk.fields[next(iter(SENSOR_FIELDS[sensor]))][3] = np.nan
        payloads.append((sensor, codec.encode_block(blk)))
    rejected = 0
    for k in range(3000):
        sensor, p = payloads[k % 2]
        b = mutated(p, rng, k)
        try:
            out = codec.decode_block("b", sensor, b)
        except ValueError:
            rejected += 1
            continue
        assert all(v.shape == out.t_ns.shape for v in out.fields.values())
    assert 1000 < rejected < 3000
