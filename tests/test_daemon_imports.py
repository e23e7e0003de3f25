"""The live daemon's import path stays free of scipy (~60-80 MB of resident memory).

Each check runs in a fresh interpreter: building the daemon from the shipped configuration
and feeding it decoded blocks is what ``buoymon run`` does before serving, so every import
the pipeline makes on its first blocks is covered, not just the module-level ones.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

REPO = Path(__file__).resolve().parents[1]

_DAEMON_PATH = r"""
import json, sys, time
from pathlib import Path
sys.path.insert(0, {repo!r})
from monitor import cmd_run
if {block_scipy}:
    cmd_run.keep_scipy_out()
import numpy as np
from monitor import zenoh_io
from monitor.blocks import SampleBlock
tmp = Path({tmp!r})
cfg = tmp / "daemon.toml"
cfg.write_text(Path({repo!r}, "monitor", "vaps_seed004.toml").read_text()
               + '\n[state]\npath = "' + str(tmp / "state.sqlite") + '"\n'
               + '[metrics]\nport = 0\n')  # any free port: other daemons may run beside
daemon = cmd_run.build_daemon(str(cfg))
codec = zenoh_io.default_codec()
t0 = 1_750_000_000 * 10**9
for k in range(25):  # 25 s of sensor time: alert rules run every 10 s
    for sensor, hz, fields in (("tension", 20, ("tension_N",)),
                               ("imu", 10, ("accel_x_mps2", "accel_y_mps2", "accel_z_mps2")),
                               ("gnss", 1, ("lat_deg", "lon_deg"))):
        t = t0 + (k * hz + np.arange(hz)) * (10**9 // hz)
        vals = {{f: np.full(hz, 3000.0 if f == "tension_N" else 0.1) for f in fields}}
        block = SampleBlock("vaps", sensor, t, vals)
        key = f"buoy/vaps/sensor/{{sensor}}"
        daemon._on_data(key, codec.encode(block), 0, None, time.monotonic())
json.dumps(daemon.full_state())
print(json.dumps({{"counters": daemon.counters,
                  "scipy": sorted(m for m, v in sys.modules.items()
                                  if m.split(".")[0] == "scipy" and v is not None)}}))
"""

_NUMBA_ALONE = r"""
import json, sys
import numba
from numba.core.registry import cpu_target

cpu_target.target_context.refresh()  # what loading the first cached kernel does
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] == "scipy")))
"""


def _run(code: str) -> object:
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_buoymon_run_builds_and_processes_without_scipy(tmp_path):
    """With ``keep_scipy_out`` (as ``buoymon run`` does) a scipy import anywhere on the path
    fails the build or the first blocks; afterwards no scipy module is loaded at all."""
    out = _run(_DAEMON_PATH.format(repo=str(REPO), tmp=str(tmp_path), block_scipy=True))
    assert out["counters"]["messages"] == 75
    assert out["counters"]["undecodable"] == out["counters"]["refused"] == 0
    assert out["scipy"] == []


def test_daemon_code_imports_no_scipy_beyond_what_numba_does(tmp_path):
    """Without the block, the daemon's own code adds no scipy module to the ones numba
    imports by itself (numba loads ``scipy`` and ``scipy.linalg`` when it is installed)."""
    numba_alone = set(_run(_NUMBA_ALONE))
    out = _run(_DAEMON_PATH.format(repo=str(REPO), tmp=str(tmp_path), block_scipy=False))
    extra = sorted(set(out["scipy"]) - numba_alone)
    assert extra == [], f"the daemon's path imports {extra[:10]}"
    assert not any(m.startswith(("scipy.signal", "scipy.optimize", "scipy.integrate"))
                   for m in out["scipy"])
