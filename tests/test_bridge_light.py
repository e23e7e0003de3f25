"""A bridge process publishes with the numpy-only encoder: it never loads numba or LLVM
(~110 MB of memory and seconds of start-up), and its blocks carry the Maine load cell's
samples exactly as the numba codec decodes them."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np

from daemon_harness import ENV, free_port
from test_bridge import LBF, MAINE, Collector, maine_lines, pytestmark  # noqa: F401

# `buoymon bridge` in a process that says afterwards which modules it had loaded; then it
# takes the numba codec's compiled encoder (importing monitor.codec alone loads no numba: its
# kernels are compiled on first use, models._jit), to show the check sees numba when it is there
_BRIDGE = r"""
import json, sys
from monitor import cli
rc = cli.main(sys.argv[1:])
heavy = lambda: sorted(m for m in sys.modules if m.split(".")[0] in ("numba", "llvmlite"))
out = {"rc": rc, "heavy": heavy()}
import monitor.codec
monitor.codec.put_payload.compiled
out["heavy_after_codec"] = len(heavy())
print(json.dumps(out))
"""


def test_bridge_process_never_imports_numba_and_its_blocks_decode_exactly(tmp_path):
    lines = maine_lines(600)
    port = free_port()
    col = Collector(port)
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[buoy]\nid = "t1"\n[bridge]\nconnect = ["tcp/127.0.0.1:{port}"]\n'
                   '[[source]]\nname = "loadcell"\nsensor = "tension"\ntransport = "stdin"\n'
                   f'columns = {{ tension_N = 2 }}\nscale = {{ tension_N = {LBF} }}\n'
                   'time_column = 0\ntime_format = "%Y-%m-%d-%H:%M:%S.%f"\n')
    try:
        p = subprocess.Popen([sys.executable, "-c", _BRIDGE, "--log-level", "warning",
                              "bridge", "--config", str(cfg)], env=ENV, stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        time.sleep(1.5)  # connected to the collector
        p.stdin.write(("\n".join(lines) + "\n").encode())
        p.stdin.close()
        deadline = time.monotonic() + 30
        got = []
        while time.monotonic() < deadline and sum(len(b) for b in got) < len(lines):
            time.sleep(0.2)
            got.extend(col.blocks())
        p.terminate()
        p.wait(30)
        out, err = p.stdout.read(), p.stderr.read()
    finally:
        col.close()
    report = json.loads(out.decode().strip().splitlines()[-1])
    assert report["rc"] == 0, err.decode()[-2000:]
    assert report["heavy"] == []
    assert report["heavy_after_codec"] > 10  # the check would see numba
    v = np.concatenate([b.fields["tension_N"] for b in got])
    exp = np.array([float(ln.split(",")[2]) * LBF for ln in lines])
    assert v.shape == exp.shape and np.all(np.abs(v - exp) <= 0.05)  # 0.1-N quanta
    assert np.abs(v - exp).max() > 0  # quantized, not passed through
