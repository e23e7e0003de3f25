"""Start-up of the command line (issue 22): what each command imports, and compilation only
where it is announced. Each check runs a fresh interpreter (what a user's command is); the
timings themselves are in bench/bench_startup.py, not here."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from monitor.cli import COMMANDS
from monitor.numba_setup import NOTICE

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`
REPO = Path(__file__).resolve().parents[1]
NOTICE_START = NOTICE.split("(")[0]
HEAVY = ("numpy", "numba", "scipy", "rerun", "zenoh", "matplotlib", "dask", "mcap")


def _python(code: str, **env: str) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO), **env},
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc


def _buoymon(*args: str, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "monitor.cli", *args], capture_output=True,
                          text=True, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO), **env},
                          timeout=600)


_IMPORTED_AFTER = """
import json, sys
from monitor.cli import main
try:
    status = main({argv!r})
except SystemExit as exc:
    status = exc.code
print(json.dumps({{"status": status, "modules": sorted(sys.modules)}}))
"""


def _imports_of(argv: list[str]) -> tuple[int, set[str], str]:
    proc = _python(_IMPORTED_AFTER.format(argv=argv))
    out = json.loads(proc.stdout.splitlines()[-1])
    return out["status"], set(out["modules"]), proc.stdout


def test_help_lists_every_command_and_imports_none_of_them():
    status, modules, out = _imports_of(["--help"])
    assert status == 0
    for name, (_, summary) in COMMANDS.items():
        assert f"    {name}" in out
        assert summary.split()[0] in out
    assert not {m for m in modules if m.split(".")[0] in HEAVY}
    assert not {m for m in modules if m.split(".")[0] in ("models", "replay")}


def test_check_config_builds_the_models_without_numba():
    status, modules, out = _imports_of(["check-config", str(REPO / "monitor" / "vaps_seed004.toml")])
    assert status == 0 and ": ok" in out
    assert "models.helix" in modules and "models.fatigue.sn_curve" in modules  # it did build them
    assert not {m.split(".")[0] for m in modules} & (set(HEAVY) - {"numpy"})


def test_every_command_registers_itself_for_its_help():
    # each table entry names the module that registers that command
    code = ("from monitor.cli import COMMANDS, main\n"
            "for name in COMMANDS:\n"
            "    try:\n"
            "        main([name, '--help'])\n"
            "    except SystemExit as exc:\n"
            "        assert exc.code == 0, name\n"
            "    else:\n"
            "        raise AssertionError(name)\n")
    out = _python(code).stdout
    assert out.count("usage: buoymon ") == len(COMMANDS)
    for name in COMMANDS:
        assert f"usage: buoymon {name} " in out


def test_a_compilation_is_announced_and_numba_starts_without_scipy():
    code = ("import sys\n"
            "from monitor.numba_setup import prepare_numba\n"
            "prepare_numba()\n"
            "import models.fatigue\n"  # looks numba up without importing it
            "import numba\n"
            "from numba.core.registry import cpu_target\n"
            "assert not [m for m in sys.modules if m.startswith('scipy') and sys.modules[m]]\n"
            "assert numba.njit(lambda x: x + 1)(1) == 2\n"  # never cached: always compiles
            "assert numba.njit(lambda x: x + 2)(1) == 3\n"
            "import scipy.signal\n"  # scipy is given back once numba is up
            "print(scipy.signal.__name__)\n")
    proc = _python(code)
    assert proc.stdout.strip() == "scipy.signal"
    assert proc.stderr.count(NOTICE_START) == 1  # once per process
    assert "__main__.<lambda>" in proc.stderr


def test_after_warmup_no_command_compiles(tmp_path):
    """`buoymon warmup` covers the kernels of simulate, replay and the library's per-call
    fatigue path: afterwards none of them announces a compilation. (The first run after a
    kernel changed compiles here, inside warmup, which is what it is for.) With --config,
    as the service runs it, it also leaves the estimator's catenary table in the model
    cache."""
    models = tmp_path / "model-cache"
    cfg = tmp_path / "deeper.toml"  # another mooring than the demo's: its own table
    cfg.write_text((REPO / "monitor" / "vaps_seed004.toml").read_text()
                   .replace("depth_m = 23.0", "depth_m = 24.0", 1))
    warm = _buoymon("warmup", "--config", str(cfg), BUOYMON_CACHE_DIR=str(models))
    assert warm.returncode == 0, warm.stderr
    assert "kernels ready" in warm.stdout
    assert sorted(p.name.split("-")[0] for p in models.iterdir()) == ["estimator"] * 2
    log = tmp_path / "x.mcap"
    sim = _buoymon("simulate", "-o", str(log), "--hours", "0.005", "--hs", "2", "--tp", "7",
                   "--seed", "3", "--load-model", "wavfor")
    assert sim.returncode == 0, sim.stderr
    rep = _python(_IMPORTED_AFTER.format(
        argv=["replay", str(log), "--report", str(tmp_path / "r.json"), "--no-progress"]),
        BUOYMON_CACHE_DIR=str(models))  # the estimator's table as warmup left it
    out = json.loads(rep.stdout.splitlines()[-1])
    assert out["status"] == 0
    assert NOTICE_START not in sim.stderr + rep.stderr
    # a log this small replays as plain Python: numba is never imported (0.55 s saved); nor
    # is anything else a replay does not use (rerun alone took 0.44 s)
    assert not {m.split(".")[0] for m in out["modules"]} & {
        "numba", "llvmlite", "rerun", "matplotlib", "zenoh", "dask", "scipy"}
    assert json.loads((tmp_path / "r.json").read_text())["samples"]["tension"]["accepted"] == 360
    # the same replay compiled (as any larger log is) loads every kernel from the cache
    big = _python("import json, sys\n"
                  "from monitor.numba_setup import prepare_numba\n"
                  "prepare_numba()\n"
                  "from monitor.config import default_config\n"
                  "from replay.runner import replay_logs\n"
                  f"r = replay_logs(default_config(), [{str(log)!r}], plain=False)\n"
                  "print(json.dumps([r.report['samples']['tension']['accepted'],\n"
                  "                  'numba' in sys.modules, 'scipy.linalg' in sys.modules]))\n")
    assert json.loads(big.stdout.splitlines()[-1]) == [360, True, False]
    assert NOTICE_START not in big.stderr, big.stderr
    lib = _python("import numpy as np\n"
                  "from monitor.numba_setup import prepare_numba\n"
                  "prepare_numba()\n"
                  "from models.fatigue import MinerAccumulator, SNCurve, StreamingRainflow\n"
                  "from models.helix import HelixCable, conductor_stress\n"
                  "rf, miner = StreamingRainflow(), MinerAccumulator(SNCurve.vaps_copper())\n"
                  "x = conductor_stress(np.array([1e3, 5e3, 1e3, 6e3, 2e3]), HelixCable.vaps_biw())\n"
                  "miner.add_cycles(*rf.feed(x), time_s=0.0)\n"
                  "miner.residue_damage(rf)\n"
                  "r, m, c = rf.residue_half_cycles()\n"
                  "miner.sn_curve.damage_per_cycle(r, m, c)\n")
    assert NOTICE_START not in lib.stderr
