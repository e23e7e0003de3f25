"""Start-up of the command line and the daemon (issue 22, part 2).

Each figure is a fresh process, as a user's command is, best of ``--runs``: wall time and
CPU time (user + system, from the child's rusage; on a shared machine the CPU figure is
the stable one, wall also counts waiting for a core). Byte code is compiled first and the
numba cache is filled by ``buoymon warmup`` ("warm"), as after ``make demo`` or the
service's pre-start step. Targets: ``--help`` and ``check-config`` under 0.3 s, ``replay``
of a tiny (36 s) log under 0.5 s warm, a cold daemon start under 5 s.

- ``--help``, ``check-config`` of the shipped configuration, ``replay`` of a 36-second
  simulated log, ``warmup`` with the cache already filled;
- daemon start: ``buoymon run`` from exec to systemd's ``READY=1`` (on ``$NOTIFY_SOCKET``:
  subscribed and serving), "cold" with an empty model cache and "warm" with the model cache
  the cold start left (the same: the estimator, whose catenary table the model cache holds,
  is built at the first motion block);
- with ``--compile``: ``warmup`` into an empty numba cache (what the first install pays).

Measured 2026-11-25 17:00 UTC on the shared 2-core Xeon (Emerald Rapids, 2.3 GHz), load
average 3-4 from other work (wall times wait for a core: CPU is the fair figure; a
replay's wall can be under its CPU, the read-ahead thread decodes on the other core), best
of 5, wall / CPU in s. "before" is main at 6054245 (``--repo`` on an export of it),
"after" this branch merged with it, in the same session:

    command                            before          after
    buoymon --help                     0.04 / 0.04     0.03 / 0.03
    buoymon check-config               0.31 / 0.21     0.16 / 0.22
    buoymon replay (36 s log)          1.23 / 0.90     0.36 / 0.46
    buoymon warmup --config (filled)   1.57 / 1.14     1.03 / 1.13
    daemon start, cold (exec->READY)   0.68 / 0.65     0.56 / 0.65
    daemon start, warm model cache     0.66 / 0.64     0.61 / 0.63

An hour earlier, against main at e1a1500 (load average 5-6): replay 0.96 / 0.99 before,
0.46 / 0.41 after; a second run at load 4-5 gave 0.89 / 0.44 after: under 0.5 s of wall
time needs a free core, the CPU time is 0.41-0.46 s.

Earlier (98e57db, before ``buoymon warmup`` and the lazy imports): --help 1.20 / 0.60,
check-config 0.92 / 0.47, replay 1.79 / 1.53; a warm-up into an empty numba cache 80.4 s
wall / 34.6 s CPU (``--compile``), a daemon start with an empty numba cache 47.3 / 13.7.
The daemon's start (0.65 s of CPU to READY=1) is far under the 5 s target once the kernels
are cached: the 11-12 s the issue measured was compilation, which the unit's
ExecStartPre (``buoymon warmup --config``) now does before ``buoymon run``.

A replay of a small log never imports numba: numba's import and its CPU target (every
type and lowering registry, loaded with the first cached kernel: some 560 modules) cost
about 0.55 s of CPU, more than such a log's loops take as plain Python. Every kernel is
one function that runs compiled or uncompiled with the same bits (models._jit.Kernel);
``buoymon replay`` runs them uncompiled when the logs inflate to at most
``replay.runner.PLAIN_PYTHON_BYTES`` (100 kB, about 3.5 minutes of the default streams; the
size is read from the files' summaries before anything else) in a process that has not
loaded numba. ``--plain-sweep`` times whole replays in fresh processes both ways (CPU s,
best of 3, after the merge, 17:08 UTC):

    log      inflated   plain   compiled
    0.6 min     20 kB    0.43       1.10
    1 min       31 kB    0.48       1.12
    2 min       57 kB    0.68       1.10
    3 min       84 kB    0.82       1.14
    5 min      137 kB    1.06       1.14
    10 min     269 kB    2.01       1.08

The 0.4-0.45 s left of a 36 s replay (cProfile): Python and numpy about 0.15 s, buoymon's
modules (configuration, pipeline, alerts, models) about 0.15 s, the reader, decoder,
validation, QARTOD, estimator and fatigue loops as plain Python about 0.1 s. Neither rerun
(0.44 s), scipy, zenoh, dask, matplotlib nor fleet's process pool is imported by a replay;
``check-config`` and ``--help`` run no kernel and never import numba.

Usage: PYTHONPATH=. python bench/bench_startup.py [--runs 5] [--compile | --plain-sweep]
"""

from __future__ import annotations

import argparse
import compileall
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def child_env(repo: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return {**env, "PYTHONPATH": str(repo), **extra}


def timed(argv: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float]:
    """(wall s, CPU s) of one run of ``buoymon argv``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "monitor.cli", *argv], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.returncode != 0:
        raise SystemExit(f"buoymon {' '.join(argv)} failed:\n{err}")
    if "compiling numerical kernels" in err and argv[0] != "warmup":
        print(f"  note: buoymon {argv[0]} compiled (the cache was not filled)")
    return wall, usage.ru_utime + usage.ru_stime


def best(runs: list[tuple[float, float]]) -> str:
    return f"{min(r[0] for r in runs):6.2f} s wall {min(r[1] for r in runs):6.2f} s CPU"


def daemon_ready(repo: Path, tmp: Path, model_cache: Path) -> tuple[float, float]:
    """(wall s from exec to READY=1, CPU s of the daemon by then) of ``buoymon run``."""
    cfg = tmp / "daemon.toml"
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg.write_text((repo / "monitor" / "vaps_seed004.toml").read_text()
                   + f'\n[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
                   f'[state]\npath = "{tmp / "state.sqlite"}"\n[metrics]\nport = 0\n')
    (tmp / "state.sqlite").unlink(missing_ok=True)
    sock_path = tmp / "notify.sock"
    sock_path.unlink(missing_ok=True)
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind(str(sock_path))
        sock.settimeout(120)
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "monitor.cli", "--log-level", "warning", "run", "--config",
             str(cfg)], cwd=tmp, stdout=subprocess.DEVNULL, stderr=open(tmp / "daemon.log", "w"),
            env=child_env(repo, NOTIFY_SOCKET=str(sock_path), BUOYMON_CACHE_DIR=str(model_cache)))
        try:
            while b"READY=1" not in sock.recv(4096):
                pass
            wall = time.perf_counter() - t0
            with open(f"/proc/{proc.pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            cpu = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        finally:
            proc.terminate()
            proc.wait(60)
    return wall, cpu


PLAIN_CHILD = """
import sys
from monitor.config import default_config
from replay.runner import replay_logs
replay_logs(default_config(), [sys.argv[1]], show_progress=False, plain=sys.argv[2] == "plain")
"""


def plain_sweep(repo: Path, tmp: Path, runs: int) -> None:
    """CPU of a replay run as plain Python and compiled (fresh processes, numba's load
    included), by the log's inflated size: where PLAIN_PYTHON_BYTES (replay.runner) sits."""
    env = child_env(repo)
    print(f"{'log':>8s} {'inflated':>10s} {'plain CPU':>10s} {'compiled CPU':>13s}")
    for minutes in (0.6, 1, 2, 3, 5, 10):
        log = tmp / f"sweep-{minutes}.mcap"
        timed(["simulate", "-o", str(log), "--hours", f"{minutes / 60:.5f}", "--hs", "2",
               "--tp", "8", "--seed", "1"], env, tmp)
        size = subprocess.run(
            [sys.executable, "-c", "import sys; from replay.log_files import inflated_size; "
             "print(inflated_size([sys.argv[1]]))", str(log)], env=env, cwd=tmp,
            capture_output=True, text=True, check=True).stdout.strip()
        cpu = {}
        for mode in ("plain", "compiled"):
            cpu[mode] = min(timed_python([PLAIN_CHILD, str(log), mode], env, tmp)[1]
                            for _ in range(runs))
        print(f"{minutes:6.1f} min {int(size) / 1e3:7.0f} kB {cpu['plain']:8.2f} s "
              f"{cpu['compiled']:11.2f} s")


def timed_python(argv: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float]:
    """(wall s, CPU s) of ``python -c argv[0] argv[1:]``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", *argv], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(proc.stderr.read().decode() if proc.stderr else "child failed")
    return time.perf_counter() - t0, usage.ru_utime + usage.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--repo", type=Path, default=REPO,
                    help="checkout to measure (default this one); one without `buoymon "
                         "warmup` fills its cache by running the commands once")
    ap.add_argument("--compile", action="store_true",
                    help="also time a warm-up into an empty numba cache (a minute or more)")
    ap.add_argument("--plain-sweep", action="store_true",
                    help="only replays of 0.6-10 min logs, as plain Python and compiled")
    args = ap.parse_args()
    repo = args.repo.resolve()
    compileall.compile_dir(repo, quiet=1, rx=re.compile(r"[/\\](\.venv|out)[/\\]"))
    env = child_env(repo)
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp_s:
        tmp = Path(tmp_s)
        log = tmp / "tiny.mcap"
        timed(["simulate", "-o", str(log), "--hours", "0.01", "--hs", "2", "--tp", "8",
               "--seed", "1"], env, tmp)
        if (repo / "replay" / "cmd_warmup.py").exists():
            timed(["warmup"], env, tmp)
            if args.plain_sweep:
                plain_sweep(repo, tmp, args.runs)
                return
        else:
            timed(["replay", str(log), "--no-progress"], env, tmp)
        print(f"{os.cpu_count()} cores, load average "
              f"{' '.join(f'{v:.1f}' for v in os.getloadavg())}; best of {args.runs}")
        cases = {
            "buoymon --help": ["--help"],
            "buoymon check-config": ["check-config", str(repo / "monitor" / "vaps_seed004.toml")],
            "buoymon replay (36 s log)": ["replay", str(log), "--report", str(tmp / "r.json"),
                                          "--no-progress"],
        }
        if (repo / "replay" / "cmd_warmup.py").exists():  # the service's pre-start step
            cases["buoymon warmup --config (filled)"] = [
                "warmup", "--config", str(repo / "monitor" / "vaps_seed004.toml")]
        for name, argv in cases.items():
            print(f"{name:34s} {best([timed(argv, env, tmp) for _ in range(args.runs)])}")
        cold, warm = [], []
        for k in range(args.runs):
            cache = tmp / f"model-cache-{k}"
            cold.append(daemon_ready(repo, tmp, cache))
            warm.append(daemon_ready(repo, tmp, cache))
        print(f"{'daemon start, cold (exec->READY)':34s} {best(cold)}")
        print(f"{'daemon start, warm model cache':34s} {best(warm)}")
        if args.compile:
            empty = tmp / "numba-cache"
            wall, cpu = timed(["warmup"], child_env(repo, NUMBA_CACHE_DIR=str(empty)), tmp)
            print(f"{'warmup into an empty numba cache':34s} {wall:6.2f} s wall {cpu:6.2f} s CPU")


if __name__ == "__main__":
    main()
