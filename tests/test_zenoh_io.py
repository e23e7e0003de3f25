"""Zenoh plumbing with real sessions on loopback, the publisher in a separate process."""

import os
import queue
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from monitor import zenoh_io
from monitor.daemon_config import ZenohConfig

REPO = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


_PUBLISHER = """
import sys, time
from monitor import zenoh_io
from monitor.daemon_config import ZenohConfig
zc = ZenohConfig(mode="client", listen=(), connect=(sys.argv[1],))
n = int(sys.argv[2])
with zenoh_io.open_session(zc) as s:
    token = s.liveliness().declare_token("buoy/b1/sensor/tension")
    pub = zenoh_io.declare_data_publisher(s, "buoy/b1/sensor/tension")
    while not pub.matching_status:
        time.sleep(0.01)
    for i in range(n):
        pub.put(i.to_bytes(4, "little") * 64)
    replies = [r.ok.payload.to_bytes() for r in s.get("buoy/b1/monitor/state", timeout=30) if r.ok]
    print(replies[0].decode(), flush=True)
    pub.undeclare()
    token.undeclare()
"""


def test_burst_across_processes_is_lossless_and_liveliness_and_queries_work():
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    zc = ZenohConfig(listen=(endpoint,))
    q = queue.SimpleQueue()
    n = 20000
    with zenoh_io.open_session(zc) as s:
        sub = zenoh_io.declare_enqueuing_subscriber(s, zenoh_io.sensor_key("b1"), q)
        live = zenoh_io.declare_liveliness_watch(s, zenoh_io.sensor_key("b1"), q)
        qa = zenoh_io.declare_deferred_queryable(s, zenoh_io.state_key("b1"), q)
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        proc = subprocess.Popen([sys.executable, "-c", _PUBLISHER, endpoint, str(n)], env=env,
                                stdout=subprocess.PIPE, text=True)
        data, alive, answered = [], [], 0
        deadline = time.monotonic() + 120
        # until everything arrived, the query was answered and the token went away again
        while (answered < 1 or len(data) < n or len(alive) < 2) and time.monotonic() < deadline:
            try:
                item = q.get(timeout=0.1)
            except queue.Empty:
                continue
            if item[0] == "data":
                data.append(item)
            elif item[0] == "alive":
                alive.append(item[1:3])
            elif item[0] == "query":  # answered on this thread, as the daemon does
                with item[1] as query:
                    query.reply(zenoh_io.state_key("b1"), b"answered")
                answered += 1
        assert proc.communicate(timeout=60)[0].strip() == "answered"
        assert len(data) == n
        assert [int.from_bytes(d[2][:4], "little") for d in data] == list(range(n))
        assert all(d[1] == "buoy/b1/sensor/tension" and d[3] > 0 for d in data)
        assert alive == [("buoy/b1/sensor/tension", True), ("buoy/b1/sensor/tension", False)]
        for obj in (sub, live, qa):
            obj.undeclare()


def test_session_listens_on_loopback_only():
    port = free_port()
    with zenoh_io.open_session(ZenohConfig(listen=(f"tcp/127.0.0.1:{port}",))) as s:
        assert s.info.zid() is not None
        with socket.socket() as c:
            c.connect(("127.0.0.1", port))  # the configured endpoint is served
        out = subprocess.run(["ss", "-ltnp"], capture_output=True, text=True).stdout \
            if os.path.exists("/usr/bin/ss") or os.path.exists("/bin/ss") else ""
        mine = [ln for ln in out.splitlines() if f"pid={os.getpid()}," in ln]
        for line in mine:  # no listening socket of this process outside loopback
            assert "127.0.0.1:" in line or "[::1]:" in line, line


def test_to_json_bytes_is_strict_json():
    import numpy as np
    doc = {"a": float("inf"), "b": np.float64(1.5), "c": np.arange(2), "d": (1, float("nan"))}
    assert zenoh_io.to_json_bytes(doc) == b'{"a":null,"b":1.5,"c":[0,1],"d":[1,null]}'


def test_bad_endpoint_fails_to_open():
    with pytest.raises(Exception):
        zenoh_io.open_session(ZenohConfig(listen=("tcp/not-an-address",)))


def test_protobuf_codec_is_the_log_format():
    import numpy as np

    from monitor.blocks import SampleBlock
    from monitor import codec

    block = SampleBlock("b1", "imu", np.array([10, 20, 35], np.int64),
                        {"accel_x_mps2": np.array([0.1, -0.2, 0.3]),
                         "accel_y_mps2": np.zeros(3), "accel_z_mps2": np.array([9.0, -1.0, 0.5])})
    zc = zenoh_io.default_codec()
    payload = zc.encode(block)
    assert payload == codec.encode_block(block)  # the same bytes as an MCAP log message
    back = zc.decode("buoy/b1/sensor/imu", payload, 123)
    assert (back.buoy_id, back.sensor, back.recv_ns) == ("b1", "imu", 123)
    assert np.array_equal(back.t_ns, block.t_ns)
    for name in block.fields:  # to within half of the 1e-4 m/s^2 quantum
        assert np.all(np.abs(back.fields[name] - block.fields[name]) <= 0.5e-4)
    spec = zc.channel_spec("imu")
    assert (spec.schema_name, spec.schema_encoding, spec.message_encoding) == (
        "buoymon.v2.ImuBlock", "protobuf", "protobuf")
    assert spec.schema_data == codec.file_descriptor_set("imu")
    with pytest.raises(ValueError):
        zc.decode("buoy/b1/sensor/imu", b"\xff\xff\xff", 0)
    with pytest.raises(ValueError, match="not of the form"):
        zc.decode("buoy/b1/status", payload, 0)
