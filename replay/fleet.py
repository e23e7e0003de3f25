"""Fleet-scale replay: many buoys, many files each, in parallel processes or on Dask.

A fleet archive is any set of MCAP files and folders (folders are searched recursively).
:func:`discover` groups the files by buoy (from their ``buoy/<id>/sensor/...`` topics) and
orders each buoy's files by their first message time. :func:`replay_buoy` replays one buoy's
files in that order through one pipeline, so its state (rainflow residue, damage, alert states)
is carried from file to file exactly as ``buoymon replay FILE1 FILE2 ...`` does: the same
reader (:class:`replay.reader.LogReader`), driver (:func:`replay.runner.run_blocks`) and report
(:func:`replay.report.build_report`). Blocks of other buoys in a shared file are skipped and
counted.

:func:`run_fleet` runs one task per buoy, serially, in a local process pool (``workers``) or on
a Dask scheduler (``cluster``). Every task is a pure function of (buoy id, files, configuration
document), so the three give bit-identical per-buoy reports. :func:`fleet_report` ranks the
buoys by risk.

Risk ranking (most at risk first): the shortest remaining life over a buoy's components
(``remaining_life_days``; a buoy with no damage rate yet ranks after every buoy with one), then
the largest damage (Miner sum incl. open residue), then the number of active alerts, then the id.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from monitor.blocks import parse_sensor_topic
from monitor.config import Config, parse_config
from monitor.viz.human import remaining_life_text

FLEET_REPORT_VERSION = 1
# forkserver: workers fork from a clean server process, never from a parent that already runs
# numba or zenoh threads (forking those can deadlock).
MP_START_METHOD = "forkserver"


@dataclass(frozen=True)
class BuoyArchive:
    """The log files of one buoy, in time order."""

    buoy_id: str
    files: tuple[str, ...]


@dataclass(frozen=True)
class BuoyJob:
    """One task: a buoy's files and the configuration document to replay them with.

    The configuration travels as its raw TOML document (plain dicts) and is re-validated in the
    worker, so a job pickles the same way for a process pool and for Dask. ``read_ahead``: the
    reader's (:class:`replay.reader.LogReader`; None: its own rule, from the CPUs of the
    process that runs the job; :func:`run_jobs` sets it for a pool).
    """

    buoy_id: str
    files: tuple[str, ...]
    config_raw: Mapping[str, Any]
    config_source: str
    read_ahead: bool | None = None


# ------------------------------------------------------------------------------ discovery


def _scan_buoys_and_start(path: Path) -> tuple[set[str], int | None]:
    """Read a file without a usable summary (damaged) for its buoys and first sensor time."""
    from replay.reader import LogReader

    reader = LogReader([path])
    buoys = {block.buoy_id for block in reader}
    firsts = [st.first_ns for st in reader.stats if st.first_ns is not None]
    return buoys, (min(firsts) if firsts else None)


def _file_buoys_and_start(path: Path) -> tuple[set[str], int | None]:
    """Buoy ids of a file's sensor channels and its first message time (ns).

    Uses the summary when the file has one; a file cut short (no footer) is read with the
    salvaging reader instead, which recovers what was written before the damage.
    """
    from mcap.reader import make_reader

    buoys: set[str] = set()
    start: int | None = None
    with open(path, "rb") as f:
        try:
            summary = make_reader(f).get_summary()
        except Exception:  # damaged file: no usable summary; scanned below
            summary = None
    if summary is not None:
        for ch in summary.channels.values():
            try:
                buoys.add(parse_sensor_topic(ch.topic)[0])
            except ValueError:  # monitor outputs (status, alerts) are not inputs
                continue
        if summary.statistics is not None and summary.statistics.message_count:
            start = int(summary.statistics.message_start_time)
    if not buoys or start is None:
        return _scan_buoys_and_start(path)
    return buoys, start


def discover(paths: Iterable[str | Path]) -> list[BuoyArchive]:
    """Group the MCAP files under ``paths`` by buoy, each buoy's files ordered by start time.

    Files are identified by resolved path, so naming a file twice (or a file and its folder)
    replays it once. A file holding several buoys is listed for each of them. Files with no
    readable sensor message are left out. Buoys are returned sorted by id.
    """
    per_buoy: dict[str, list[tuple[int, str]]] = {}
    seen: set[Path] = set()
    from replay.log_files import expand_paths

    for path in expand_paths(paths, recursive=True, missing="raise"):
        real = path.resolve()
        if real in seen:
            continue
        seen.add(real)
        buoys, start = _file_buoys_and_start(real)
        for b in buoys:
            per_buoy.setdefault(b, []).append((start if start is not None else 0, str(real)))
    return [BuoyArchive(b, tuple(f for _, f in sorted(files)))
            for b, files in sorted(per_buoy.items())]


# ------------------------------------------------------------------------------ one buoy


def make_jobs(archives: Sequence[BuoyArchive], config: Config) -> list[BuoyJob]:
    """One job per buoy; the fleet shares ``config``, with each buoy's own id."""
    from monitor.shore import config_for_buoy  # the daemon's configuration: only for a fleet

    return [BuoyJob(a.buoy_id, a.files, config_for_buoy(config, a.buoy_id).raw, config.source)
            for a in archives]


def replay_buoy(job: BuoyJob) -> dict[str, Any]:
    """Replay one buoy's files in order through one pipeline; return its replay report.

    Runs in a worker process (pool or Dask): module-level, pure, returns plain JSON data.
    """
    from replay.reader import LogReader
    from replay.report import build_report
    from replay.runner import read_summary, run_blocks
    from replay.spans import of_buoy

    config = parse_config(job.config_raw, source=job.config_source)
    reader = LogReader(list(job.files), read_ahead=job.read_ahead,
                       max_ahead_s=config.ordering.max_ahead_s)
    ignored: dict[str, int] = {}
    pipeline, _ = run_blocks(config, of_buoy(reader, job.buoy_id, ignored))
    report = build_report(pipeline.config, pipeline.report(), list(job.files),
                          read_summary(reader.stats))
    if ignored:
        report["inputs"]["ignored_blocks_of_other_buoys"] = ignored
    pipeline.close()
    return report


# ------------------------------------------------------------------------------ many buoys


def _largest_first(jobs: Sequence[BuoyJob]) -> list[int]:
    """Submission order: biggest archives first, so no worker is left with a long tail."""
    sizes = [sum(os.path.getsize(f) for f in j.files) for j in jobs]
    return sorted(range(len(jobs)), key=lambda i: (-sizes[i], jobs[i].buoy_id))


def _run_serial(jobs: Sequence[BuoyJob], done: Callable[[str], None]) -> list[dict[str, Any]]:
    out = []
    for job in jobs:
        out.append(replay_buoy(job))
        done(job.buoy_id)
    return out


def pool_jobs(jobs: Sequence[BuoyJob], processes: int, cpus: int | None = None
              ) -> list[BuoyJob]:
    """``jobs`` as ``processes`` local workers run them: each reads ahead only if the workers
    leave a core free for its thread (:func:`replay.chunks.read_ahead_pays` with the parent's
    ``cpus``, default its usable CPUs; the workers inherit its affinity). A job that says
    already keeps its choice."""
    from dataclasses import replace

    from replay.chunks import read_ahead_pays

    pays = read_ahead_pays(processes, cpus)
    return [j if j.read_ahead is not None else replace(j, read_ahead=pays) for j in jobs]


def _run_pool(jobs: Sequence[BuoyJob], workers: int, done: Callable[[str], None]
              ) -> list[dict[str, Any]]:
    from concurrent.futures import ProcessPoolExecutor, as_completed  # 25 ms: only for a pool
    from multiprocessing import get_context

    results: list[dict[str, Any] | None] = [None] * len(jobs)
    processes = min(workers, len(jobs))
    jobs = pool_jobs(jobs, processes)
    with ProcessPoolExecutor(max_workers=processes,
                             mp_context=get_context(MP_START_METHOD)) as pool:
        futures = {pool.submit(replay_buoy, jobs[i]): i for i in _largest_first(jobs)}
        for fut in as_completed(futures):
            i = futures[fut]
            results[i] = fut.result()
            done(jobs[i].buoy_id)
    return results  # type: ignore[return-value]


def _run_dask(jobs: Sequence[BuoyJob], address: str, done: Callable[[str], None]
              ) -> list[dict[str, Any]]:
    """Run on an existing Dask scheduler. The workers need this package installed and the log
    files at the same paths (a shared file system)."""
    from dask.distributed import Client, as_completed as dask_completed

    results: list[dict[str, Any] | None] = [None] * len(jobs)
    with Client(address, set_as_default=False) as client:
        # pure=False: a rerun after a model change must recompute, never reuse cached results
        futures = {client.submit(replay_buoy, jobs[i], pure=False): i
                   for i in _largest_first(jobs)}
        for fut in dask_completed(list(futures), loop=client.loop):
            i = futures[fut]
            results[i] = fut.result()
            done(jobs[i].buoy_id)
    return results  # type: ignore[return-value]


def run_jobs(jobs: Sequence[BuoyJob], *, workers: int = 1, cluster: str | None = None,
             on_done: Callable[[str], None] | None = None) -> list[dict[str, Any]]:
    """Run replay jobs; return their reports in the order of ``jobs``.

    ``workers`` > 1 uses a local process pool; ``cluster`` (``tcp://HOST:PORT``) a Dask
    scheduler instead. ``on_done(buoy_id)`` is called as each job's result is collected.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers = {workers!r}: must be an integer >= 1")
    if cluster is not None and not (isinstance(cluster, str) and "://" in cluster):
        raise ValueError(f"cluster = {cluster!r}: must be a scheduler address like tcp://HOST:PORT")
    done = on_done or (lambda _b: None)
    if not jobs:
        return []
    if cluster is not None:
        return _run_dask(jobs, cluster, done)
    if workers > 1 and len(jobs) > 1:
        return _run_pool(jobs, workers, done)
    return _run_serial(jobs, done)


def run_fleet(archives: Sequence[BuoyArchive], config: Config, *, workers: int = 1,
              cluster: str | None = None, on_done: Callable[[str], None] | None = None
              ) -> list[dict[str, Any]]:
    """Replay every buoy with one configuration; reports in the order of ``archives``."""
    return run_jobs(make_jobs(archives, config), workers=workers, cluster=cluster,
                    on_done=on_done)


# ------------------------------------------------------------------------------ fleet report


def active_alerts(alerts: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """Alerts firing at the end of the replay: the last transition per fingerprint is firing."""
    last: dict[str, Mapping[str, Any]] = {}
    for rec in alerts:
        last[rec["fingerprint"]] = rec
    return [r for r in last.values() if r["state"] == "firing"]


def _risk_key(entry: Mapping[str, Any]) -> tuple:
    life = entry["min_remaining_life_days"]
    return (life is None, math.inf if life is None else life, -entry["max_damage"],
            -entry["active_alerts"], entry["buoy_id"])


def fleet_report(reports: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Rank the buoys by risk (see the module doc); per buoy and component: damage, remaining
    life and active alerts."""
    buoys = []
    for rep in reports:
        active = active_alerts(rep["alerts"])
        comps = {}
        for name, c in rep["components"].items():
            comps[name] = {
                "damage": c["damage"],
                "damage_committed": c["damage_committed"],
                "damage_rate_per_day": c["damage_rate_per_day"],
                "remaining_life_days": c["remaining_life_days"],
                "max_stress_Pa": c["max_stress_Pa"],
                "active_alerts": [f"{a['rule']}:{a['severity']}" for a in active
                                  if a["labels"].get("component") == name],
            }
        lives = [c["remaining_life_days"] for c in comps.values()
                 if c["remaining_life_days"] is not None]
        buoys.append({
            "buoy_id": rep["buoy_id"],
            "time_start": rep["time_start"],
            "time_end": rep["time_end"],
            "files": len(rep["inputs"]["files"]),
            "min_remaining_life_days": min(lives) if lives else None,
            "max_damage": max((c["damage"] for c in comps.values()), default=0.0),
            "active_alerts": len(active),
            "alerts": [{"rule": a["rule"], "severity": a["severity"],
                        "component": a["labels"].get("component"), "since_ns": a["starts_at_ns"]}
                       for a in active],
            "components": comps,
        })
    buoys.sort(key=_risk_key)
    for rank, b in enumerate(buoys, start=1):
        b["rank"] = rank
    return {"fleet_report_version": FLEET_REPORT_VERSION, "buoys": buoys,
            "ranking": "min remaining_life_days, then max damage, then active alerts"}


def fleet_summary_text(fleet: Mapping[str, Any]) -> str:
    """The ranked fleet as a table, one line per buoy and component."""
    lines = [f"fleet: {len(fleet['buoys'])} buoy(s), most at risk first",
             f"  {'rank':>4s} {'buoy':16s} {'component':20s} {'damage':>11s} {'rate/day':>11s} "
             f"{'life left':>11s}  active alerts"]
    for b in fleet["buoys"]:
        for j, (name, c) in enumerate(b["components"].items()):
            life = c["remaining_life_days"]
            rate = c["damage_rate_per_day"]
            lines.append(
                f"  {b['rank'] if j == 0 else '':>4} {b['buoy_id'] if j == 0 else '':16s} "
                f"{name:20s} {c['damage']:11.3e} {'-' if rate is None else format(rate, '11.3e'):>11s} "
                # null: nothing accrues (docs/REPORT_FORMAT.md); in words, as the report's page
                f"{remaining_life_text(math.inf if life is None else life):>11s}  "
                f"{', '.join(c['active_alerts']) or '-'}")
        # alerts on a sensor stream or the line (stale, rejected_rate, tension_high): no
        # component's row would show them
        other = [a for a in b["alerts"] if a["component"] not in b["components"]]
        if other:
            lines.append(f"  {'':>4} {'':16s} also active: " + ", ".join(
                f"{a['rule']}:{a['severity']} ({a['component']})" for a in other))
    return "\n".join(lines)


def write_reports(report_dir: str | Path, reports: Sequence[Mapping[str, Any]],
                  fleet: Mapping[str, Any]) -> list[Path]:
    """``<dir>/buoys/<buoy_id>.json`` per buoy and ``<dir>/fleet.json``; return the paths."""
    from replay.report import atomic_write_text, write_report

    out = Path(report_dir)
    paths = []
    for rep in reports:
        p = out / "buoys" / f"{rep['buoy_id']}.json"
        write_report(p, rep)
        paths.append(p)
    p = out / "fleet.json"
    atomic_write_text(p, json.dumps(fleet, indent=2, allow_nan=False) + "\n")
    paths.append(p)
    return paths
