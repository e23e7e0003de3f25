"""Fleet-scale replay: many buoys, many files each, in parallel processes or on Dask.

A fleet archive is any set of MCAP files and folders. :func:`discover` groups the files by
buoy (from their ``buoy/<id>/sensor/...`` topics) and orders each buoy's files by their first
message time; :func:`run_fleet` replays each buoy's files in order with its state carried from
file to file (the same path as ``buoymon replay`` on one buoy), one buoy per task, and
:func:`fleet_report` ranks the buoys by risk.

Every task is a pure function of (buoy id, files, configuration), so a serial run, a
process pool and a Dask cluster give bit-identical per-buoy reports.
"""

from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from mcap.reader import make_reader

from monitor.blocks import parse_sensor_topic


@dataclass(frozen=True)
class BuoyArchive:
    """The log files of one buoy, in time order."""

    buoy_id: str
    files: tuple[str, ...]


def _log_files(paths: Iterable[str | Path]) -> list[Path]:
    found: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found.extend(sorted(p.rglob("*.mcap")))
        elif p.is_file():
            found.append(p)
        else:
            raise FileNotFoundError(f"no such log file or folder: {p}")
    return found


def _file_buoys_and_start(path: Path) -> tuple[set[str], int]:
    """Buoy ids of a file's sensor channels and its first sensor time (ns).

    Uses the summary when the file has one; a file cut short (no footer) is scanned with the
    streaming reader instead, which recovers what was written before the damage.
    """
    buoys: set[str] = set()
    start = math.inf
    with open(path, "rb") as f:
        try:
            summary = make_reader(f).get_summary()
        except Exception:  # damaged file: no usable summary; fall back to a scan below
            summary = None
        if summary is not None and summary.channels:
            for ch in summary.channels.values():
                try:
                    buoys.add(parse_sensor_topic(ch.topic)[0])
                except ValueError:
                    continue
            if summary.statistics is not None and summary.statistics.message_count:
                start = summary.statistics.message_start_time
    if not buoys or start is math.inf:
        from replay.reader import scan_file_buoys

        buoys, start = scan_file_buoys(path)
    return buoys, int(start) if start is not math.inf else 0


def discover(paths: Iterable[str | Path]) -> list[BuoyArchive]:
    """Group the MCAP files under ``paths`` by buoy, each buoy's files ordered by start time.

    Files are identified by resolved path, so naming a file twice (or a file and its
    folder) replays it once. Buoys are returned sorted by id.
    """
    per_buoy: dict[str, list[tuple[int, str]]] = {}
    seen: set[Path] = set()
    for path in _log_files(paths):
        real = path.resolve()
        if real in seen:
            continue
        seen.add(real)
        buoys, start = _file_buoys_and_start(real)
        for b in buoys:
            per_buoy.setdefault(b, []).append((start, str(real)))
    return [
        BuoyArchive(b, tuple(f for _, f in sorted(files)))
        for b, files in sorted(per_buoy.items())
    ]
