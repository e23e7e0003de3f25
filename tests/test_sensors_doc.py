"""docs/SENSORS.md and the README's "Connect your instruments" hold working material: every
configuration example parses (and says what it claims), and the custom driver, run as it is
printed, publishes what a polled load cell on a pseudo-terminal answers."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
import tomllib
import tty
from pathlib import Path

import numpy as np

from daemon_harness import ENV, free_port
from monitor.bridge.config import parse_bridge_config
from test_bridge import Collector

REPO = Path(__file__).resolve().parents[1]
DOC = (REPO / "docs" / "SENSORS.md").read_text()


def blocks(text: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", text, re.S)


def test_every_configuration_example_parses():
    head, *examples = blocks(DOC, "toml")
    sources = []
    for ex in examples:
        cfg = parse_bridge_config(tomllib.loads(head + ex))
        assert cfg.buoy_id == "vaps" and cfg.connect == ("tcp/127.0.0.1:7447",)
        sources.extend(cfg.sources)
    by = {s.name: s for s in sources}
    assert {s.transport for s in sources} == {"serial", "tcp_server", "file", "stdin"}
    assert by["gps"].format == "nmea" and by["replayed"].format == "csv"
    assert by["imu"].scale["accel_z_mps2"] == 9.80665
    assert by["wavebuoy"].scale["heave_m"] == 0.01 and by["wavebuoy"].host == "127.0.0.1"
    (readme,) = blocks((REPO / "README.md").read_text(), "toml")
    assert [s.name for s in parse_bridge_config(tomllib.loads(readme)).sources] == [
        "loadcell", "gps"]


def test_the_reference_names_every_source_key():
    from monitor.bridge.config import SourceConfig

    ref = DOC.split("### `[[source]]`")[1].split("## Time")[0]
    documented = set(re.findall(r"^\| `(\w+)`(?:, `(\w+)`)?", ref, re.M))
    names = {n for pair in documented for n in pair if n}
    assert names == set(SourceConfig.__struct_fields__)


def test_the_custom_driver_as_printed_publishes_a_polled_load_cell(tmp_path):
    (code,) = blocks(DOC.split("## A driver of your own")[1], "python")
    assert len(code.strip().splitlines()) < 20 + 2  # "under 20 lines" of code, + 2 imports
    port = free_port()
    script = tmp_path / "driver.py"
    script.write_text(code.replace('"vaps", "tcp/127.0.0.1:7447"', f'"t1", "tcp/127.0.0.1:{port}"'))
    master, slave = os.openpty()
    tty.setraw(slave)
    answers = ["  +100.5 kg", "  +101.0 kg", "#!garbled", "  +99.25 kg"]
    stop = threading.Event()

    def load_cell() -> None:  # answers each "W\r" with the next reading
        k, buf = 0, b""
        while not stop.is_set():
            try:
                buf += os.read(master, 64)
            except OSError:  # the driver closed its end: the test is over
                return
            while b"W\r" in buf:
                buf = buf.split(b"W\r", 1)[1]
                os.write(master, (answers[k % len(answers)] + "\r\n").encode())
                k += 1

    col = Collector(port)
    cell = threading.Thread(target=load_cell, daemon=True)
    cell.start()
    p = subprocess.Popen([sys.executable, str(script), os.ttyname(slave)], env=ENV,
                         stderr=subprocess.PIPE, text=True)
    try:
        got: list = []
        deadline = time.monotonic() + 60
        while len(got) < 2 and time.monotonic() < deadline and p.poll() is None:
            time.sleep(0.2)
            got.extend(col.blocks())
    finally:
        p.kill()
        _, err = p.communicate(timeout=10)
        stop.set()
        os.close(slave)  # the load cell's read ends
        cell.join(5)
        os.close(master)
        col.close()
    assert len(got) >= 2, err
    for b in got:
        assert b.sensor == "tension" and np.all(np.diff(b.t_ns) > 0)
        # the readings (kg) in newtons, each within half the 0.1 N quantum of the wire format
        kg = np.array([100.5, 101.0, 99.25])
        off = np.abs(b.fields["tension_N"][:, None] - kg[None, :] * 9.80665).min(axis=1)
        assert np.all(off <= 0.05 + 1e-9), off
        assert (b.t_ns[-1] - b.t_ns[0]) >= 1_000_000_000 and len(b) >= 5  # ~10 readings / s


def test_check_config_validates_a_bridge_file_as_the_bridge_reads_it(tmp_path, capsys):
    from monitor.cli import main

    good = tmp_path / "bridge.toml"
    good.write_text('[buoy]\nid = "vaps"\n[bridge]\nconnect = ["tcp/127.0.0.1:7447"]\n'
                    '[[source]]\nname = "lc"\nsensor = "tension"\ntransport = "udp"\n'
                    'port = 10110\nformat = "delimited"\ncolumns = { tension_N = 1 }\n')
    assert main(["check-config", str(good)]) == 0
    assert "lc: udp -> tension" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text(good.read_text().replace('sensor = "tension"', 'sensor = "tensoin"'))
    assert main(["check-config", str(bad)]) == 2
    assert "source[0].sensor = 'tensoin': must be one of" in capsys.readouterr().err
