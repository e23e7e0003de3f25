"""``buoymon simulate --publish``: the simulated buoy played over Zenoh on loopback."""

import queue
import socket
import time

import numpy as np
import pytest

from monitor import zenoh_io
from monitor.cli import main
from monitor.daemon_config import ZenohConfig
from replay.reader import LogReader

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_simulate_publish_delivers_every_block_paced(tmp_path, capsys):
    port = free_port()
    log = tmp_path / "sim.mcap"
    q: queue.SimpleQueue = queue.SimpleQueue()
    listener = ZenohConfig(mode="peer", listen=(f"tcp/127.0.0.1:{port}",))
    with zenoh_io.open_session(listener) as session:
        sub = zenoh_io.declare_enqueuing_subscriber(session, "buoy/vaps/sensor/**", q)
        start = time.monotonic()
        rc = main(["simulate", "-o", str(log), "--hours", "0.01", "--hs", "1.5", "--tp", "5.25",
                   "--seed", "3", "--publish", f"tcp/127.0.0.1:{port}", "--speed", "20"])
        elapsed = time.monotonic() - start
        deadline = time.monotonic() + 10
        got = []
        while time.monotonic() < deadline and len(got) < 144:
            try:
                got.append(q.get(timeout=0.5))
            except queue.Empty:
                pass
        sub.undeclare()
    assert rc == 0
    out = capsys.readouterr().out
    assert f"publishing to tcp/127.0.0.1:{port} at 20x real time" in out
    assert "published 144 blocks" in out  # 36 s x (tension, imu, motion, gnss)
    assert elapsed > 35 / 20 * 0.9  # paced by sensor time
    codec = zenoh_io.default_codec()
    blocks = [codec.decode(key, payload, recv) for _, key, payload, recv, _, _ in got]
    assert len(blocks) == 144
    sent = [b for b in blocks if b.sensor == "tension"]
    logged = [b for b in LogReader([log], coalesce=False) if b.sensor == "tension"]
    assert len(sent) == len(logged) == 36
    np.testing.assert_array_equal(np.concatenate([b.t_ns for b in sent]),
                                  np.concatenate([b.t_ns for b in logged]))
    np.testing.assert_array_equal(np.concatenate([b.fields["tension_N"] for b in sent]),
                                  np.concatenate([b.fields["tension_N"] for b in logged]))


@pytest.mark.parametrize("endpoint, message", [
    ("tcp/192.0.2.7:7447", "192.0.2.7 is not a loopback address"),
    ("tcp/buoy.example.org:7447", "not a loopback address"),
    ("127.0.0.1", "expected PROTO/HOST:PORT"),
])
def test_publish_refuses_non_loopback_endpoints(tmp_path, capsys, endpoint, message):
    rc = main(["simulate", "--hours", "0.01", "--hs", "1.5", "--tp", "5.25", "--seed", "3",
               "--publish", endpoint])
    assert rc == 2 and message in capsys.readouterr().err


def test_output_or_publish_is_required(capsys):
    assert main(["simulate", "--hours", "0.01", "--hs", "1.5", "--tp", "5.25", "--seed", "3"]) == 2
    assert "-o/--output is required" in capsys.readouterr().err


def test_publish_module_says_when_nothing_could_be_sent(tmp_path, capsys):
    """A missing or unreadable log: exit status 1 and a message (was "0", status 0); a
    malformed endpoint is a usage error (was a zenoh.ZError traceback)."""
    from replay.publish import main as publish_main  # noqa: PLC0415

    garbage = tmp_path / "g.mcap"
    garbage.write_bytes(b"not an mcap file")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    for log in (tmp_path / "nothere.mcap", garbage):
        assert publish_main([str(log), "--connect", endpoint]) == 1
        assert f"no sensor block could be read from ['{log}']" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        publish_main([str(garbage), "--connect", "garbage"])
    assert exc.value.code == 2 and "'garbage' is not a Zenoh endpoint" in capsys.readouterr().err
    # a speed or linger that cannot be: a usage error (was a ValueError traceback from the
    # player, once the session was open)
    for option, value, message in (("--speed", "0", "--speed 0.0: must be a number > 0"),
                                   ("--speed", "-1", "--speed -1.0: must be a number > 0"),
                                   ("--speed", "nan", "--speed nan: must be a number > 0"),
                                   ("--linger-s", "-5", "--linger-s -5.0: must be a number")):
        with pytest.raises(SystemExit) as exc:
            publish_main([str(garbage), "--connect", endpoint, option, value])
        assert exc.value.code == 2 and message in capsys.readouterr().err
