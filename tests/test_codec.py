"""Block payload codec: exact bytes, round trips, and decoding by generic protobuf tooling."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor import codec

T0 = 1_700_000_000_123_456_789


def _block(sensor: str, t: np.ndarray, seed: int = 0) -> SampleBlock:
    rng = np.random.default_rng(seed)
    return SampleBlock("b-1", sensor, t.astype(np.int64),
                       {f: rng.normal(size=t.shape[0]) for f in SENSOR_FIELDS[sensor]})


def _generic_class(sensor: str):
    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(codec.file_descriptor_set(sensor)).file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(codec.schema_name(sensor)))


def _equal(a: SampleBlock, b: SampleBlock) -> bool:
    return (a.sensor == b.sensor and np.array_equal(a.t_ns, b.t_ns)
            and all(np.array_equal(a.fields[k], b.fields[k]) for k in a.fields))


def test_exact_bytes_of_a_regular_tension_block():
    t = np.array([T0, T0 + 50_000_000], np.int64)
    blk = SampleBlock("b", "tension", t, {"tension_N": np.array([1000.5, -2.25])})
    # field 1 sfixed64, field 2 varint 50e6 = 0x80 0xE1 0xEB 0x17, field 4 packed 2 doubles
    expected = (b"\x09" + struct.pack("<q", T0) + b"\x10\x80\xe1\xeb\x17"
                + b"\x22\x10" + struct.pack("<2d", 1000.5, -2.25))
    assert codec.encode_block(blk) == expected


def test_irregular_times_use_zigzag_offsets():
    t = np.array([T0, T0 + 3, T0 - 1], np.int64)  # offsets 0, 3, -1 -> zigzag 0, 6, 1
    blk = SampleBlock("b", "tension", t, {"tension_N": np.zeros(3)})
    payload = codec.encode_block(blk)
    assert payload[9:14] == b"\x1a\x03\x00\x06\x01"
    assert _equal(codec.decode_block("b", "tension", payload), blk)


@pytest.mark.parametrize("sensor", sorted(SENSOR_FIELDS))
@pytest.mark.parametrize("kind", ["regular", "irregular", "single"])
def test_round_trip_and_generic_protobuf_agree(sensor, kind):
    rng = np.random.default_rng(3)
    if kind == "regular":
        t = T0 + np.arange(37) * 100_000_000
    elif kind == "irregular":
        t = T0 + np.cumsum(rng.integers(1, 10**9, 25))
    else:
        t = np.array([T0])
    blk = _block(sensor, np.asarray(t, np.int64))
    payload = codec.encode_block(blk)
    assert _equal(codec.decode_block("b-1", sensor, payload), blk)
    m = _generic_class(sensor).FromString(payload)
    n = len(blk)
    assert m.t0_ns == T0 if kind != "irregular" else m.t0_ns == t[0]
    times = (m.t0_ns + np.array(m.t_offset_ns, np.int64) if len(m.t_offset_ns)
             else m.t0_ns + m.period_ns * np.arange(n))
    assert np.array_equal(times, blk.t_ns)
    for f in SENSOR_FIELDS[sensor]:
        assert np.array_equal(np.array(getattr(m, f)), blk.fields[f])
    # and what the generic runtime serializes, our decoder reads
    assert _equal(codec.decode_block("b-1", sensor, m.SerializeToString()), blk)


def test_numba_bulk_encoder_matches_reference_encoder():
    rng = np.random.default_rng(5)
    t = np.concatenate([T0 + np.arange(10) * 10**8,
                        T0 + 10**9 + np.cumsum(rng.integers(1, 10**7, 7))])
    vals = rng.normal(size=(3, t.shape[0]))
    out = np.zeros(codec.payload_bound(t.shape[0], 3), np.uint8)
    for a, b in ((0, 10), (10, 17), (3, 4)):
        end = codec.put_payload(out, 0, t, vals, a, b)
        assert out[:end].tobytes() == codec.encode_samples(t[a:b], list(vals[:, a:b]))


def test_unpacked_fields_unknown_fields_and_any_order_decode():
    msg = _generic_class("tension")(t0_ns=T0, period_ns=5, tension_N=[1.0, 2.0])
    extra = b"\x78\x2a"  # field 15, varint 42: unknown, must be skipped
    # tension_N written unpacked (wire type 1 per value) and before t0
    unpacked = b"\x21" + struct.pack("<d", 1.0) + b"\x21" + struct.pack("<d", 2.0)
    payload = extra + unpacked + b"\x09" + struct.pack("<q", T0) + b"\x10\x05"
    blk = codec.decode_block("b", "tension", payload)
    assert blk.t_ns.tolist() == [T0, T0 + 5] and blk.fields["tension_N"].tolist() == [1.0, 2.0]
    assert msg.ParseFromString(payload) == len(payload)


@pytest.mark.parametrize("payload, reason", [
    (b"\x09" + struct.pack("<q", T0) + b"\x10\x05\x22\x10" + bytes(8), "malformed"),  # cut short
    (b"\x09" + struct.pack("<q", T0) + b"\x22\x10" + bytes(16), "no period_ns"),
    (b"\x10\x05\x22\x08" + bytes(8), "t0_ns missing"),
    (b"\x09" + struct.pack("<q", T0) + b"\x10\x05\x22\x07" + bytes(7), "malformed"),  # 7 bytes
    (b"\x09" + struct.pack("<q", T0) + b"\x1a\x01\x00\x22\x10" + bytes(16), "disagree"),
])
def test_malformed_payloads_raise_value_error(payload, reason):
    with pytest.raises(ValueError, match=reason):
        codec.decode_block("b", "tension", payload)


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="unknown sensor 'sonar'"):
        codec.file_descriptor_set("sonar")
    empty = SampleBlock("b", "tension", np.empty(0, np.int64), {"tension_N": np.empty(0)})
    with pytest.raises(ValueError, match="empty block"):
        codec.encode_block(empty)


def test_field_numbers_are_read_from_the_stored_schema():
    fds = descriptor_pb2.FileDescriptorSet.FromString(codec.file_descriptor_set("gnss"))
    for fld in fds.file[0].message_type[0].field:
        if fld.name == "lon_deg":
            fld.number = 9
    name = "buoymon.v1.GnssBlock"
    numbers = codec.field_numbers_from_schema(fds.SerializeToString(), name, "gnss")
    assert numbers == (1, 2, 3, (4, 9))
    with pytest.raises(ValueError, match="missing fields"):
        codec.field_numbers_from_schema(codec.file_descriptor_set("gnss"), name, "imu")


def test_shipped_proto_file_matches_the_runtime_schemas():
    from pathlib import Path

    shipped = Path(codec.__file__).with_name("buoymon.proto").read_text()
    assert shipped == codec.proto_text()
    assert "  repeated double accel_z_mps2 = 6;  // m/s^2" in shipped
    assert "  sfixed64 t0_ns = 1;  // ns" in shipped
