"""Which log files to read, and their time spans from the cheap ends of the files."""

from __future__ import annotations

import logging
import struct
from os import PathLike
from pathlib import Path
from typing import Iterable, Sequence

from replay.mcap_scan import summary_records
from monitor.mcap_file import MAGIC, OP_CHUNK, OP_CHUNK_INDEX, OP_MESSAGE, OP_STATISTICS

log = logging.getLogger(__name__)


def expand_paths(paths: Iterable[str | PathLike], *, recursive: bool = False,
                 missing: str = "keep") -> list[Path]:
    """Files as given; a directory expands to its ``*.mcap`` files sorted by name (with
    ``recursive``, those of its sub-folders too). A path that does not exist is kept
    (``missing="keep"``: reading it then reports it unreadable), logged and skipped
    (``"skip"``) or a FileNotFoundError (``"raise"``)."""
    if missing not in ("keep", "skip", "raise"):
        raise ValueError(f"missing = {missing!r}: must be 'keep', 'skip' or 'raise'")
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.rglob("*.mcap") if recursive else p.glob("*.mcap"))
            if not found:  # a mistyped folder among others would otherwise pass unnoticed
                log.warning("%s: no *.mcap file in this folder%s", p,
                            "" if recursive else " (its sub-folders not searched)")
            out.extend(found)
        elif p.exists() or missing == "keep":
            out.append(p)
        elif missing == "raise":
            raise FileNotFoundError(f"no such log file or folder: {p}")
        else:
            log.error("%s does not exist; skipped", p)
    return out


def _file_span(path: Path) -> tuple[int, int] | None:
    """(first, last) message log time of one file from its summary Statistics record."""
    try:
        with open(path, "rb") as f:
            size = f.seek(0, 2)
            for op, content in summary_records(f, size):
                if op == OP_STATISTICS and len(content) >= 42:
                    t0, t1 = struct.unpack_from("<QQ", content, 26)
                    return (t0, t1) if t1 >= t0 > 0 else None
    except OSError:
        pass
    return None


def time_span(paths: Sequence[str | PathLike] | str | PathLike) -> tuple[int, int] | None:
    """(first, last) message log time over the files, from their summary Statistics records.

    Cheap (reads only the ends of the files), for progress bars; files without a readable
    footer/summary are left out, and None is returned when no file has one.
    """
    if isinstance(paths, (str, PathLike)):
        paths = [paths]
    spans = [sp for sp in map(_file_span, expand_paths(paths)) if sp is not None]
    if not spans:
        return None
    return min(sp[0] for sp in spans), max(sp[1] for sp in spans)


def inflated_size(paths: Sequence[str | PathLike]) -> int | None:
    """Bytes the files hold once their chunks are decompressed, from their summaries (the
    chunk indexes' compressed and uncompressed sizes; anything outside chunks counts as
    stored): a bound on the samples to read known before reading any (every sample takes at
    least a byte). Cheap (reads only the ends of the files); None when a file has no
    readable summary (cut short, or not MCAP)."""
    total = 0
    for path in expand_paths(paths):
        try:
            with open(path, "rb") as f:
                size = f.seek(0, 2)
                chunks, indexed = None, 0
                for op, content in summary_records(f, size):
                    if op == OP_STATISTICS and len(content) >= 26:
                        chunks = struct.unpack_from("<I", content, 22)[0]  # chunk_count
                    elif op == OP_CHUNK_INDEX and len(content) >= 16:
                        # the record ends with compressed_size, uncompressed_size (u64)
                        compressed, uncompressed = struct.unpack_from("<QQ", content,
                                                                      len(content) - 16)
                        size += uncompressed - compressed
                        indexed += 1
        except OSError:
            return None
        if chunks is None or indexed != chunks:  # no statistics, or chunks not indexed
            return None
        total += size
    return total


def file_start_ns(path: str | PathLike) -> int | None:
    """The first message log time of a file: from its summary, else from the header of its
    first chunk (a file cut short by a crash); None when neither can be read. Cheap."""
    span = _file_span(Path(path))
    if span is not None:
        return span[0]
    try:
        with open(path, "rb") as f:
            if f.read(8) != MAGIC:
                return None
            while True:
                head = f.read(9)
                if len(head) < 9:
                    return None
                op, ln = struct.unpack("<BQ", head)
                if op in (OP_CHUNK, OP_MESSAGE):  # a chunk's start time; a message's own
                    head = f.read(14)
                    if len(head) < 14:
                        return None
                    return struct.unpack_from("<Q", head, 0 if op == OP_CHUNK else 6)[0]
                if op == 0 or op >= 0x10:
                    return None
                f.seek(ln, 1)
    except OSError:
        return None
