"""Test oracle of ``replay.reader.LogReader``: ``mcap``'s own reader and the generic
protobuf runtime (moved out of the production reader, issue 18)."""

from __future__ import annotations

from os import PathLike
from typing import Sequence

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from monitor.blocks import SENSOR_FIELDS, SampleBlock, parse_sensor_topic
from replay.log_files import expand_paths


def _generic_values(field) -> np.ndarray:
    """A value field as decoded by the generic protobuf runtime, as float64 samples: a
    ``Quantized`` message by the arithmetic of docs/LOG_FORMAT.md, or v1 doubles as they are."""
    if not hasattr(field, "quantum"):
        return np.array(field, np.float64)
    v = np.cumsum(np.array(field.delta, np.int64)).astype(np.float64) * field.quantum
    v[np.array(field.raw_index, np.int64)] = np.array(field.raw_value, np.float64)
    return v


def reference_blocks(paths: Sequence[str | PathLike] | str | PathLike) -> list[SampleBlock]:
    """Slow reference: ``mcap``'s own reader and the generic protobuf runtime, one block per
    message, sorted by (publish time, topic, read order), every copy kept.

    Independent of :mod:`monitor.codec`'s decoder and of this module's record parsing; used by
    tests to check the fast path. Undamaged files only.
    """
    if isinstance(paths, (str, PathLike)):
        paths = [paths]
    rows = []
    for path in expand_paths(paths):
        with open(path, "rb") as f:
            classes: dict[int, type] = {}
            for schema, channel, msg in make_reader(f).iter_messages(log_time_order=False):
                if schema is None or schema.encoding != "protobuf":
                    continue
                buoy, sensor = parse_sensor_topic(channel.topic)
                cls = classes.get(schema.id)
                if cls is None:
                    pool = descriptor_pool.DescriptorPool()
                    for fd in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
                        pool.Add(fd)
                    cls = classes[schema.id] = message_factory.GetMessageClass(
                        pool.FindMessageTypeByName(schema.name))
                m = cls.FromString(msg.data)
                names = list(SENSOR_FIELDS[sensor])
                n = len(_generic_values(getattr(m, names[0])))
                if len(m.t_offset_ns):
                    t = m.t0_ns + np.array(m.t_offset_ns, np.int64)
                else:
                    t = m.t0_ns + m.period_ns * np.arange(n, dtype=np.int64)
                blk = SampleBlock(buoy, sensor, t.astype(np.int64),
                                  {k: _generic_values(getattr(m, k)) for k in names},
                                  msg.log_time)
                rows.append((msg.publish_time, channel.topic, len(rows), msg.data, blk))
    rows.sort(key=lambda r: r[:3])
    return [blk for *_, blk in rows]
