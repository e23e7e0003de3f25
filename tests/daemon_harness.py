"""Test harness for the daemon's mechanics, independent of the physics pipeline.

``python tests/daemon_harness.py run CFG.toml [DELAY_S [STATE_DELAY_S]]`` runs a :class:`monitor.daemon.Daemon` for buoy
``b1`` with :class:`FakePipeline` (a sum of tension with the pipeline's per-stream
re-delivery check) and :class:`FakeCodec`. ``python tests/daemon_harness.py publish ENDPOINT
N SPEED`` plays ``N`` one-second tension blocks through :func:`monitor.publisher.publish_blocks`.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from monitor.blocks import SENSOR_FIELDS, SampleBlock, parse_sensor_topic  # noqa: E402
from monitor.events import ComponentStep, StepResult  # noqa: E402
from monitor.recorder import ChannelSpec  # noqa: E402

BUOY = "b1"
T0_NS = 1_750_000_000 * 10**9
RATE_HZ = 20


class FakeCodec:
    """JSON header line + raw little-endian arrays (tests only; the product uses protobuf)."""

    def encode(self, block: SampleBlock) -> bytes:
        head = json.dumps({"n": len(block)}).encode() + b"\n"
        return head + block.t_ns.astype("<i8").tobytes() + b"".join(
            block.fields[f].astype("<f8").tobytes() for f in SENSOR_FIELDS[block.sensor])

    def decode(self, topic: str, payload: bytes, recv_ns: int) -> SampleBlock:
        buoy, sensor = parse_sensor_topic(topic)
        try:
            head, body = payload.split(b"\n", 1)
            n = int(json.loads(head)["n"])
            t = np.frombuffer(body[: 8 * n], "<i8").astype(np.int64)
            names = list(SENSOR_FIELDS[sensor])
            fields = {f: np.frombuffer(body[8 * n * (i + 1): 8 * n * (i + 2)], "<f8").copy()
                      for i, f in enumerate(names)}
        except (ValueError, KeyError) as exc:
            raise ValueError(f"bad payload: {exc}") from None
        return SampleBlock(buoy, sensor, t, fields, recv_ns)

    def channel_spec(self, sensor: str) -> ChannelSpec:
        return ChannelSpec(f"fake.{sensor}", "jsonschema", b'{"type":"object"}', "json")


class FakePipeline:
    """Damage = sum of accepted tension samples / 1e9; samples at or before a stream's last
    time are rejected as duplicates, NaNs as nan: the contract the real pipeline keeps."""

    def __init__(self, state: Any = None, delay_s: float = 0.0, state_delay_s: float = 0.0,
                 alerts_raw: Any = None, sinks: Any = ()) -> None:
        from monitor.alerts.config import AlertsConfig
        from monitor.alerts.engine import AlertEngine

        state = state or {}
        self.buoy_id = BUOY
        # an alert engine without sensor-time rules, so the daemon attaches alert delivery
        # (Zenoh keys, outbox channels) exactly as `buoymon run` does
        self.alerts = AlertEngine.from_config(alerts_raw or AlertsConfig(), BUOY, {})
        self.delay_s = delay_s  # simulated processing time per block
        self.state_delay_s = state_delay_s  # simulated time to take a checkpoint
        self.sinks = tuple(sinks)  # the daemon's, fixed at construction as the real pipeline's
        self.last_t = dict(state.get("last_t", {}))
        self.total = float(state.get("total", 0.0))
        self.accepted = dict(state.get("accepted", {}))
        self.rejected = {k: dict(v) for k, v in state.get("rejected", {}).items()}

    def process(self, block: SampleBlock) -> StepResult:
        if block.sensor == "waves":  # stands for any block the real pipeline refuses
            raise ValueError("waves blocks are refused by the fake pipeline")
        time.sleep(self.delay_s)
        last = self.last_t.get(block.sensor, -1)
        new = block.t_ns > last
        ok = new & np.isfinite(block.fields["tension_N"]) if block.sensor == "tension" else new
        if block.sensor == "tension":
            for v in block.fields["tension_N"][ok]:  # sequential: independent of block sizes
                self.total += float(v) / 1e9
        if ok.any():
            self.last_t[block.sensor] = int(block.t_ns[ok][-1])
        rej = self.rejected.setdefault(block.sensor, {"duplicate": 0, "nan": 0})
        rej["duplicate"] += int((~new).sum())
        rej["nan"] += int((new & ~ok).sum())
        self.accepted[block.sensor] = self.accepted.get(block.sensor, 0) + int(ok.sum())
        comp = ComponentStep("conductor", np.empty(0), np.empty(0), np.empty(0), np.empty(0),
                             self.total, self.total, 0.0, float("inf"), 0.0)
        return StepResult(BUOY, block.sensor, self.now_ns, np.empty(0, np.int64), np.empty(0),
                          "measured", float("nan"), float("nan"), {"conductor": comp},
                          int(ok.sum()), dict(rej))

    @property
    def now_ns(self) -> int:
        return int(max(self.last_t.values(), default=0))

    def status(self) -> dict[str, Any]:
        return {
            "buoy_id": BUOY, "now_ns": self.now_ns,
            "load_source": "measured" if self.total else "none",
            "load_t_ns": self.last_t.get("tension"),
            "measured_tension_N": None, "estimated_tension_N": None,
            "components": {"conductor": {"damage": self.total, "damage_committed": self.total,
                                         "damage_rate_per_day": 0.0,
                                         "remaining_life_days": None}},
            "streams": {s: {"last_t_ns": self.last_t.get(s, 0), "accepted": n,
                            "rejected": dict(self.rejected.get(s, {}))}
                        for s, n in self.accepted.items()},
        }

    def state(self) -> dict[str, Any]:
        time.sleep(self.state_delay_s)
        return {"last_t": dict(self.last_t), "total": self.total,
                "accepted": dict(self.accepted), "rejected": self.rejected}


def tension_blocks(n_blocks: int, seed: int = 1) -> list[SampleBlock]:
    """Deterministic 1-s blocks of 20 Hz tension."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n_blocks):
        t = T0_NS + (k * RATE_HZ + np.arange(RATE_HZ, dtype=np.int64)) * (10**9 // RATE_HZ)
        out.append(SampleBlock(BUOY, "tension", t,
                               {"tension_N": 5000.0 + 1000.0 * rng.standard_normal(RATE_HZ)}))
    return out


def expected_total(blocks: list[SampleBlock]) -> float:
    p = FakePipeline()
    for b in blocks:
        p.process(b)
    return p.total


def main(argv: list[str]) -> int:
    from monitor.daemon import Daemon
    from monitor.daemon_config import parse_daemon_sections
    from monitor.logs import setup_logging

    setup_logging("warning")
    if argv[0] == "run":
        from monitor.alerts.config import AlertsConfig
        from monitor.cmd_run import AlertDelivery
        from monitor.schema import read_toml

        delay = float(argv[2]) if len(argv) > 2 else 0.0
        state_delay = float(argv[3]) if len(argv) > 3 else 0.0
        raw = read_toml(argv[1])  # the daemon's sections and the alert rules, parsed once
        alerts = AlertsConfig.from_dict(raw.get("alerts"))
        daemon = Daemon(BUOY, parse_daemon_sections(raw),
                        lambda state, sinks: FakePipeline(state, delay, state_delay, alerts,
                                                             sinks),
                        FakeCodec(),
                        attach=lambda session, pipe: [AlertDelivery(session, pipe, alerts)])
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: daemon.stop())
        daemon.run()
        return 0
    if argv[0] == "publish":
        from monitor import zenoh_io
        from monitor.publisher import publish_blocks, publisher_config

        speed = float(argv[3]) or None
        with zenoh_io.open_session(publisher_config([argv[1]])) as s:
            n = publish_blocks(s, tension_blocks(int(argv[2])), FakeCodec(), speed)
        print(n, flush=True)
        return 0
    raise SystemExit(f"unknown harness command {argv[0]!r}")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))


# ---- helpers for tests that drive daemon processes --------------------------------------------

import atexit  # noqa: E402
import os  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import threading  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write_config(path: Path, port: int, state: Path, extra: str = "", record: Path | None = None,
                 checkpoint_s: float = 0.5, tension_age_s: float = 1.0, health: str = "") -> Path:
    rec = f'[record]\ndir = "{record}"\nflush_interval_s = 0.5\n' if record else ""
    if "[metrics]" not in extra:  # a port of its own: tests run beside other daemons
        extra += f"[metrics]\nport = {free_port()}\n"
    path.write_text(
        f'[buoy]\nid = "{BUOY}"\n'
        f'[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\nstatus_interval_s = 0.5\n'
        f'[state]\npath = "{state}"\ncheckpoint_interval_s = {checkpoint_s}\n'
        f'[health]\ndata_age_timeout_s = {{ tension = {tension_age_s} }}\n' + health + rec
        + extra)
    return path


class DaemonProcess:
    """A daemon subprocess with its own sd_notify socket (as systemd would provide)."""

    def __init__(self, cmd: list[str], workdir: Path, env: dict[str, str] | None = None) -> None:
        self.notify_path = str(workdir / f"notify-{os.getpid()}-{id(self)}")
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(self.notify_path)
        # stderr to a file: a pipe nobody reads would block the daemon once full
        self.stderr_path = workdir / f"daemon-{id(self)}.log"
        self._stderr_file = open(self.stderr_path, "w")
        self.proc = subprocess.Popen(
            cmd, env={**ENV, **(env or {}), "NOTIFY_SOCKET": self.notify_path,
                      "WATCHDOG_USEC": "2000000"},
            stdout=subprocess.DEVNULL, stderr=self._stderr_file)
        # a test that fails before stopping its daemon must not leave it running
        atexit.register(self._kill_if_alive)
        self.messages: list[str] = []
        # read notifications all the time, as systemd does
        self._reader = threading.Thread(target=self._read_notify, daemon=True)
        self._reader.start()

    def _read_notify(self) -> None:
        while True:
            try:
                data = self.sock.recv(4096).decode()
            except OSError:  # socket closed
                return
            self.messages.extend(data.split("\n"))

    def wait_for(self, message: str, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while message not in self.messages:
            if time.monotonic() > deadline or self.proc.poll() is not None:
                raise AssertionError(f"daemon sent no {message!r} in {timeout} s; "
                                     f"exit={self.proc.poll()} stderr={self._stderr()}")
            time.sleep(0.02)

    def _stderr(self) -> str:
        return self.stderr_path.read_text()[-3000:]

    def terminate(self, timeout: float = 30.0) -> int:
        self.proc.terminate()
        rc = self.proc.wait(timeout)
        self.close()
        return rc

    def _kill_if_alive(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def kill9(self) -> None:
        self.proc.kill()
        self.proc.wait(10)
        self.close()

    def close(self) -> None:
        self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
        self._stderr_file.close()
        if os.path.exists(self.notify_path):
            os.unlink(self.notify_path)


def query_state(port: int, timeout: float = 10.0, buoy: str = BUOY) -> dict[str, Any] | None:
    """The daemon's ``monitor/state`` answer, or None if it did not answer."""
    from monitor import zenoh_io
    from monitor.daemon_config import ZenohConfig

    zc = ZenohConfig(mode="client", listen=(), connect=(f"tcp/127.0.0.1:{port}",))
    with zenoh_io.open_session(zc) as s:
        for reply in s.get(zenoh_io.state_key(buoy), timeout=timeout):
            if reply.ok:
                return json.loads(reply.ok.payload.to_bytes())
    return None


def wait_until_state(port: int, pred, timeout: float = 60.0, buoy: str = BUOY) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        last = query_state(port, buoy=buoy)
        if last is not None and pred(last):
            return last
        time.sleep(0.2)
    raise AssertionError(f"daemon state never matched; last: {str(last)[:2000]}")
