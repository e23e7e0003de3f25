"""MCAP recorder: hourly rotation, periodic flush + fsync, files of a killed recorder replay."""

import os
import signal
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader

from monitor import codec
from monitor.blocks import SampleBlock
from monitor.recorder import JSON_OBJECT, ChannelSpec, McapRecorder
from replay.reader import LogReader

REPO = Path(__file__).resolve().parents[1]
H = 3_600_000_000_000  # one hour in ns
T0 = 1_700_000_000 * 1_000_000_000 // H * H  # a whole hour
SPEC = ChannelSpec("buoymon.v1.TensionBlock", "protobuf", b"\x0a\x00", "protobuf")


def _read(path, salvage=False):
    with open(path, "rb") as f:
        if not salvage:
            return [(c.topic, s.encoding, s.name, m.log_time, m.publish_time, m.data)
                    for s, c, m in make_reader(f).iter_messages()]
        out = []
        try:
            for s, c, m in NonSeekingReader(f).iter_messages(log_time_order=False):
                out.append((c.topic, m.log_time, m.data))
        except (McapError, EOFError, struct.error):
            pass  # the truncated tail after the last flush
        return out


def test_rotates_hourly_and_keeps_payloads_and_times(tmp_path):
    rec = McapRecorder(tmp_path, rotate_s=3600, flush_interval_s=5)
    times = [T0 + k * 30 * 60 * 1_000_000_000 for k in range(5)]  # every 30 min over 2 h
    for i, t in enumerate(times):
        rec.write("buoy/b1/sensor/tension", b"p%d" % i, SPEC, t, t - 1000)
        rec.write("buoy/b1/monitor/status", b'{"i":%d}' % i, JSON_OBJECT, t + 1, 0)
    rec.close()
    names = [os.path.basename(p) for p in rec.files]
    assert names == ["buoymon-20231114T220000Z.mcap", "buoymon-20231114T230000Z.mcap",
                     "buoymon-20231115T000000Z.mcap"]
    per_file = [_read(p) for p in rec.files]
    assert [len(m) for m in per_file] == [4, 4, 2]
    topic, enc, name, log_t, pub_t, data = per_file[1][0]
    assert (topic, enc, name, log_t, pub_t, data) == (
        "buoy/b1/sensor/tension", "protobuf", "buoymon.v1.TensionBlock", times[2],
        times[2] - 1000, b"p2")
    status = per_file[1][1]
    assert status[1:3] == ("jsonschema", "buoymon.v1.Json")
    assert status[4] == times[2] + 1  # publish_time 0 would mean "unset": log time is used
    assert rec.messages == 10


def test_restart_in_the_same_hour_never_overwrites(tmp_path):
    for k in range(2):
        rec = McapRecorder(tmp_path)
        rec.write("t", b"x", JSON_OBJECT, T0 + k, T0 + k)
        rec.close()
    assert sorted(os.listdir(tmp_path)) == ["buoymon-20231114T220000Z-1.mcap",
                                            "buoymon-20231114T220000Z.mcap"]


def test_flush_interval_is_in_log_time(tmp_path):
    rec = McapRecorder(tmp_path, flush_interval_s=2)
    rec.write("t", b"a", JSON_OBJECT, T0, T0)  # first write flushes (nothing flushed before)
    rec.write("t", b"b", JSON_OBJECT, T0 + 1_000_000_000, T0)
    assert not rec.maybe_flush(T0 + 1_500_000_000)
    assert rec.maybe_flush(T0 + 2_000_000_000)
    assert not rec.maybe_flush(T0 + 9_000_000_000)  # nothing new to flush
    rec.close()


_KILLED = """
import sys, time
from monitor.recorder import JSON_OBJECT, McapRecorder
rec = McapRecorder(sys.argv[1], flush_interval_s=3600)
t0 = int(sys.argv[2])
for i in range(300):
    rec.write("buoy/b1/sensor/tension", b"msg%04d" % i + b"." * 200, JSON_OBJECT, t0 + i, t0 + i)
rec.flush()
for i in range(300, 350):  # written after the last flush: may be lost, must not break the rest
    rec.write("buoy/b1/sensor/tension", b"msg%04d" % i, JSON_OBJECT, t0 + i, t0 + i)
print("flushed", flush=True)
time.sleep(60)
"""


def test_file_of_a_killed_recorder_salvages_to_the_last_flush(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, "-c", _KILLED, str(tmp_path), str(T0)], env=env,
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "flushed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    (path,) = [tmp_path / p for p in os.listdir(tmp_path)]
    got = _read(path, salvage=True)
    assert len(got) >= 300
    assert [m[2][:7] for m in got[:300]] == [b"msg%04d" % i for i in range(300)]
    assert [m[1] for m in got[:300]] == [T0 + i for i in range(300)]


def test_record_command_stamps_documents_with_their_sensor_time():
    """`buoymon record` gives a status or alert document its sensor time as publish time, as
    the daemon's own recording does; other documents get the receive time."""
    from monitor import cmd_record, zenoh_io

    class Capture:
        def __init__(self):
            self.calls = []

        def write(self, key, payload, spec, log_time_ns, publish_time_ns):
            self.calls.append((key, log_time_ns, publish_time_ns))

    cap, recv = Capture(), 1_800_000_000 * 10**9
    codec = zenoh_io.ProtobufCodec()
    for key, payload in (("buoy/b1/monitor/status", b'{"now_ns": 1700000000000000000}'),
                         ("buoy/b1/alerts/x", b'{"at_ns": 1700000000500000000, "state": "firing"}'),
                         ("buoy/b1/monitor/other", b'{"n": 1}'),
                         ("buoy/b1/monitor/status", b'{"now_ns": true}'),
                         ("buoy/b1/monitor/broken", b"{not json"),
                         ("buoy/b1/alerts/x", b"")):  # a DELETE: nothing to keep
        cmd_record._write(cap, codec, key, payload, recv)
    assert cap.calls == [
        ("buoy/b1/monitor/status", recv, 1_700_000_000_000_000_000),
        ("buoy/b1/alerts/x", recv, 1_700_000_000_500_000_000),
        ("buoy/b1/monitor/other", recv, recv),
        ("buoy/b1/monitor/status", recv, recv),
        ("buoy/b1/monitor/broken", recv, recv)]


def test_a_killed_recording_with_a_damaged_first_chunk_decodes_the_later_ones(tmp_path):
    """The recorder writes the logs' layout (monitor.mcap_file): channel definitions at top
    level, so losing the chunk with a channel's first messages, in a file without summary
    (killed), costs those messages only. (mcap's Writer put the definition inside that chunk:
    every later message of the channel was then undecodable.)"""
    spec = ChannelSpec(codec.schema_name("tension"), "protobuf",
                       codec.file_descriptor_set("tension"), "protobuf")
    rec = McapRecorder(tmp_path, flush_interval_s=10)
    s = 1_000_000_000
    for k in range(60):  # a chunk per 10 s
        t = T0 + k * s + np.arange(20, dtype=np.int64) * (s // 20)
        block = SampleBlock("b1", "tension", t, {"tension_N": k * 20 + np.arange(20.0)})
        rec.write("buoy/b1/sensor/tension", codec.encode_block(block), spec, T0 + (k + 1) * s,
                  int(t[0]))
    rec.close()
    (path,) = rec.files
    with open(path, "rb") as f:
        chunks = sorted(make_reader(f).get_summary().chunk_indexes,
                        key=lambda c: c.chunk_start_offset)
    first, last = chunks[0], chunks[-1]
    data = bytearray(Path(path).read_bytes()[:last.chunk_start_offset + last.chunk_length])
    data[first.chunk_start_offset + first.chunk_length - 5] ^= 0xFF  # its compressed records
    killed = tmp_path / "killed.mcap"  # no DataEnd, summary or footer
    killed.write_bytes(bytes(data))
    reader = LogReader(killed, coalesce=True)
    values = np.concatenate([b.fields["tension_N"] for b in reader])
    st = reader.stats[0]
    lost = st.lost[0].end_ns - T0  # the first chunk's log times: seconds 1 .. n
    n_first = lost // s
    assert 0 < n_first < 60 and not st.skipped and not st.complete
    assert np.array_equal(values, np.arange(n_first * 20, 60 * 20.0))


def test_record_command_without_a_daemon_is_a_clear_error(tmp_path):
    """Nothing listens on the daemon's endpoint: exit status 1 and a message naming the buoy,
    the endpoint and the likely cause (was a zenoh.ZError traceback)."""
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg = tmp_path / "cfg.toml"
    cfg.write_text((REPO / "monitor" / "vaps_seed004.toml").read_text()
                   + f'\n[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\n')
    p = subprocess.run([sys.executable, "-m", "monitor.cli", "record", "--config", str(cfg),
                        "-o", str(tmp_path / "rec")], capture_output=True, text=True,
                       timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert p.returncode == 1 and "Traceback" not in p.stderr
    assert (f"cannot reach the daemon of buoy 'vaps' at ['tcp/127.0.0.1:{port}'] ([zenoh] of "
            f"{cfg}): is `buoymon run` running?") in p.stderr
