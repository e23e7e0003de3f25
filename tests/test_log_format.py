"""The log format as a user meets it: decoded with ``mcap`` + ``mcap-protobuf-support`` alone
(docs/LOG_FORMAT.md's recipe), its size, and logs of the first format (v1) still read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from monitor.blocks import SENSOR_FIELDS
from monitor.quanta import DEFAULT_QUANTA
from mcap_oracle import reference_blocks
from replay.reader import LogReader
from replay.simulate import SimConfig, simulate

V1_LOG = Path(__file__).with_name("data") / "v1_log.mcap"
T0 = 946_684_800_000_000_000  # 2000-01-01, the fixture's first sample


def _docs_recipe(q) -> np.ndarray:
    """docs/LOG_FORMAT.md: value[i] = quantum * (delta[0] + ... + delta[i]), then raw samples."""
    v = np.cumsum(np.array(q.delta, dtype=np.int64)).astype(np.float64) * q.quantum
    v[np.array(q.raw_index, dtype=np.int64)] = np.array(q.raw_value, dtype=np.float64)
    return v


def _by_topic(blocks) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    out: dict[str, list] = {}
    for b in blocks:
        out.setdefault(b.sensor, []).append((b.t_ns, np.vstack(list(b.fields.values()))))
    return {k: (np.concatenate([t for t, _ in v]), np.concatenate([x for _, x in v], axis=1))
            for k, v in out.items()}


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory):
    """Half an hour of the default simulated streams (one waves sample), NaN and spike faults."""
    path = tmp_path_factory.mktemp("fmt") / "sim.mcap"
    summary = simulate(SimConfig(hours=0.5, hs_m=2.0, tp_s=8.0, seed=3, nans=0.002,
                                 spikes=0.001), path)
    return path, summary


def test_mcap_and_mcap_protobuf_support_alone_decode_the_log(sim_log):
    path, summary = sim_log
    got: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, _, m in reader.iter_decoded_messages():
            sensor = channel.topic.rsplit("/", 1)[1]
            names = list(SENSOR_FIELDS[sensor])
            assert schema.name == f"buoymon.v2.{m.DESCRIPTOR.name}"
            for name in names:
                assert getattr(m, name).quantum == DEFAULT_QUANTA[name]
            values = np.vstack([_docs_recipe(getattr(m, name)) for name in names])
            n = values.shape[1]
            t = (m.t0_ns + np.array(m.t_offset_ns, np.int64) if len(m.t_offset_ns)
                 else m.t0_ns + m.period_ns * np.arange(n, dtype=np.int64))
            got.setdefault(sensor, []).append((t, values))
    ours = _by_topic(LogReader(path))
    assert set(got) == set(ours) == {"tension", "imu", "motion", "gnss", "waves"}
    for sensor, parts in got.items():
        t = np.concatenate([p[0] for p in parts])
        v = np.concatenate([p[1] for p in parts], axis=1)
        assert np.array_equal(t, ours[sensor][0])
        assert v.view(np.int64).tolist() == ours[sensor][1].view(np.int64).tolist()  # bit for bit
        assert t.shape[0] == summary.samples[sensor]
    assert np.isnan(ours["tension"][1]).sum() > 10  # NaN faults survive as NaN


def test_default_streams_cost_at_most_12_bytes_per_tension_sample(sim_log):
    path, summary = sim_log
    per_sample = path.stat().st_size / summary.samples["tension"]
    assert 5.0 < per_sample <= 12.0  # 38 with float64 samples at zstd level 1


def test_v1_log_of_packed_doubles_is_still_read():
    """tests/data/v1_log.mcap: written by the writer of the first format (float64 samples):
    tension 1000 + 0.25 i + sin(i / 3) at 20 Hz with a NaN at i = 7, imu cos(i k / 7) at 10 Hz,
    gnss 43 + 1e-6 i, -70 - 1e-6 i at 1 Hz, from 2000-01-01."""
    reader = LogReader(V1_LOG)
    s = _by_topic(reader)
    i = np.arange(100)
    tension = 1000.0 + 0.25 * i + np.sin(i / 3.0)
    tension[7] = np.nan
    assert np.array_equal(s["tension"][0], T0 + i * 50_000_000)
    assert np.array_equal(s["tension"][1][0], tension, equal_nan=True)
    j = np.arange(50)
    assert np.array_equal(s["imu"][1], np.vstack([np.cos(j * k / 7.0) for k in (1, 2, 3)]))
    g = np.arange(5)
    assert np.array_equal(s["gnss"][1], np.vstack([43.0 + 1e-6 * g, -70.0 - 1e-6 * g]))
    st = reader.stats[0]
    assert st.complete and not st.lost and st.bad_payloads == 0 and st.messages == 15
    # the generic reference path reads it the same
    ref = _by_topic(reference_blocks(V1_LOG))
    for sensor, (t, v) in s.items():
        assert np.array_equal(ref[sensor][0], t)
        assert np.array_equal(ref[sensor][1], v, equal_nan=True)
