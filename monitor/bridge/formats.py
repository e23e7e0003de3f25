"""Instrument lines -> timed samples: NMEA 0183 GNSS, configurable delimited lines, CSV.

Each parser takes one decoded line and the logger's receive time (ns) and returns
``(t_ns, values, time_source)``: the values in the order of the stream's fields
(:data:`monitor.blocks.SENSOR_FIELDS`), ``time_source`` ``"instrument"`` or ``"receive"``;
or raises :class:`Rejected` with a short reason (the counter's name).

Delimited lines with the instrument's time also have a bulk parser (:func:`bulk_parser`):
all the lines of one read at once, when every one of them is clean (printable
ASCII, one column count, numbers and times that read); otherwise it gives None and the lines
are read one by one, so every rejection is counted as above. One by one a line costs ~3 us
of Python; in bulk builtins loop over the cells (bench/bench_bridge.py).
"""

from __future__ import annotations

import math
import re
from datetime import datetime, timezone
from itertools import repeat
from operator import add, floordiv, mul
from typing import Any, Callable, NamedTuple

import pynmea2

from monitor.blocks import SENSOR_FIELDS
from monitor.bridge.config import SourceConfig

Sample = tuple[int, list[float], str]


class Rejected(ValueError):
    """A line that gives no sample; ``str(exc)`` is the reason counted."""


def _value(text: str) -> float:
    try:
        v = float(text.strip())
    except ValueError:
        raise Rejected("non_numeric") from None
    if not math.isfinite(v):
        raise Rejected("non_numeric")
    return v


_UNIX = re.compile(r"([0-9]+)(?:\.([0-9]+))?")
_T_MAX = 2**63  # ns since the epoch beyond int64 (the year 2262) are no time a block holds


def instrument_time(text: str, fmt: str) -> int:
    """Sensor time (ns since the epoch, UTC) from a time cell: ``unix`` seconds, or a
    ``strptime`` format (a time without offset is UTC)."""
    text = text.strip()
    if fmt == "unix":  # exact to the ns (a float would not be); before 1970 is no real time
        m = _UNIX.fullmatch(text)
        if m is None:
            raise Rejected("bad_time")
        t = int(m[1]) * 1_000_000_000 + int(((m[2] or "") + "000000000")[:9])
        if t >= _T_MAX:
            raise Rejected("bad_time")
        return t
    try:
        dt = datetime.strptime(text, fmt)
    except ValueError:
        raise Rejected("bad_time") from None
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=timezone.utc)
    t = (int(dt.timestamp()) * 10**9) + dt.microsecond * 1000
    if not -_T_MAX <= t < _T_MAX:
        raise Rejected("bad_time")
    return t


class Samples(NamedTuple):
    """Samples of a bulk parser: times (ns) and a list of values per field."""

    t_ns: list[int]
    columns: list[list[float]]
    time_source: str


_PRINTABLE = bytes(range(0x20, 0x7F))
_DIGITS = b"0123456789"


def unix_times(cells: list[bytes]) -> list[int] | None:
    """ns since the epoch of ``unix`` time cells (no blanks) that all share one layout:
    digits, optionally a point and digits, at the same places (a logger's fixed format);
    exact as :func:`instrument_time`. None for anything else. Builtins over all the cells
    at once: a numpy call costs as much as a few lines."""
    n, width = len(cells), len(cells[0])
    joined = b"".join(cells)
    point = cells[0].find(b".")
    if width == 0 or len(joined) != width * n or point == 0 or point == width - 1:
        return None
    if point < 0:
        if joined.translate(None, _DIGITS):
            return None
        t = list(map(mul, map(int, cells), repeat(1_000_000_000)))
    else:  # a point in each cell, at the same place, and nothing but digits around it
        if joined.translate(None, _DIGITS) != b"." * n or joined[point::width] != b"." * n:
            return None
        frac = width - point - 1
        digits = map(int, map(bytes.replace, cells, repeat(b"."), repeat(b"")))
        t = (list(map(mul, digits, repeat(10 ** (9 - frac)))) if frac <= 9
             else list(map(floordiv, digits, repeat(10 ** (frac - 9)))))  # beyond ns: cut
    return t if max(t) < _T_MAX else None


def delimited_bulk(cfg: SourceConfig) -> Callable[[list[bytes], int], Samples | None] | None:
    """The bulk parser of :func:`delimited` (module docstring) for a source with a time
    column and a one-character ASCII separator (lines joined with it split back into the
    same cells); None for others (a source timed at the read has one time per read: its
    lines go one by one)."""
    if cfg.time_column is None or len(cfg.separator) != 1 or not cfg.separator.isascii():
        return None
    sep = cfg.separator.encode()
    specs = [(cfg.columns[f], cfg.scale[f], cfg.offset[f]) for f in SENSOR_FIELDS[cfg.sensor]]
    need = max([*cfg.columns.values(), cfg.time_column]) + 1
    time_column, time_format = cfg.time_column, cfg.time_format

    def parse_many(lines: list[bytes], recv_ns: int) -> Samples | None:
        m = lines[0].count(sep) + 1
        text = sep.join(lines)
        if (m < need or text.translate(None, _PRINTABLE)
                or len(set(map(bytes.count, lines, repeat(sep)))) != 1):
            return None
        cells = text.split(sep)  # the lines' cells, row after row
        cols = []
        try:  # each value as one by one: float(cell) * scale + offset
            for c, k, o in specs:
                col = list(map(add, map(mul, map(float, cells[c::m]), repeat(k)), repeat(o)))
                if not all(map(math.isfinite, col)):
                    return None
                cols.append(col)
            if time_format == "unix":
                t = unix_times(list(map(bytes.strip, cells[time_column::m])))
            else:
                t = [instrument_time(c.decode(), time_format) for c in cells[time_column::m]]
        except ValueError:  # Rejected is a ValueError
            return None
        return None if t is None else Samples(t, cols, "instrument")

    return parse_many


def delimited(cfg: SourceConfig) -> Callable[[str, int], Sample]:
    """A ``separator``-delimited line with ``columns`` (field -> index), ``scale`` and
    ``offset`` per field (value = raw x scale + offset), and an optional ``time_column``."""
    # (column, scale, offset) per field, in the stream's order: the per-line loop is the
    # bridge's hot path (bench/bench_bridge.py)
    specs = [(cfg.columns[f], cfg.scale[f], cfg.offset[f]) for f in SENSOR_FIELDS[cfg.sensor]]
    need = max([*cfg.columns.values(), cfg.time_column or 0]) + 1
    sep, time_column, time_format = cfg.separator, cfg.time_column, cfg.time_format

    def parse(line: str, recv_ns: int) -> Sample:
        cells = line.split(sep)
        if len(cells) < need:
            raise Rejected("columns")
        try:  # float() takes the cell's surrounding blanks
            vals = [float(cells[c]) * k + o for c, k, o in specs]
        except ValueError:
            raise Rejected("non_numeric") from None
        if not all(map(math.isfinite, vals)):
            raise Rejected("non_numeric")
        if time_column is None:
            return recv_ns, vals, "receive"
        return instrument_time(cells[time_column], time_format), vals, "instrument"

    return parse


def csv_header(cfg: SourceConfig) -> Callable[[str, int], Sample]:
    """The columns of ``buoymon import``: a header line naming ``time`` (ISO 8601) or
    ``time_s`` (Unix seconds) and the stream's fields; later header lines (a logger
    restarting its file) are read again."""
    fields = list(SENSOR_FIELDS[cfg.sensor])
    layout: dict[str, int] = {}

    def parse(line: str, recv_ns: int) -> Sample:
        cells = [c.strip() for c in line.split(",")]
        if any(c in ("time", "time_s") for c in cells):
            missing = [f for f in fields if f not in cells]
            if missing:
                raise Rejected("header")
            layout.clear()
            layout.update({c: i for i, c in enumerate(cells)})
            raise Rejected("header_read")
        if not layout:
            raise Rejected("no_header")
        if len(cells) != len(layout):
            raise Rejected("columns")
        vals = [_value(cells[layout[f]]) for f in fields]
        if "time_s" in layout:
            return instrument_time(cells[layout["time_s"]], "unix"), vals, "instrument"
        t = cells[layout["time"]].replace("Z", "+00:00")
        try:
            dt = datetime.fromisoformat(t)
        except ValueError:
            raise Rejected("bad_time") from None
        if dt.tzinfo is None:
            dt = dt.replace(tzinfo=timezone.utc)
        return int(dt.timestamp()) * 10**9 + dt.microsecond * 1000, vals, "instrument"

    return parse


def nmea(cfg: SourceConfig) -> Callable[[str, int], Sample]:
    """GGA and RMC sentences (checksums required and verified) -> the gnss stream. GGA carries
    no date: it takes the last valid RMC's, else the receive time's UTC date. A receiver
    sends both for each fix: the second of a fix's time is ``repeat_fix``, as other
    sentences (GSA, GSV, VTG, ...) are ``other_sentence``: counted, not faults."""
    state: dict[str, Any] = {"date": None, "t": None}

    def parse(line: str, recv_ns: int) -> Sample:
        try:
            msg = pynmea2.parse(line.strip(), check=True)
        except pynmea2.ChecksumError:
            raise Rejected("checksum") from None
        except (pynmea2.ParseError, pynmea2.SentenceTypeError, ValueError, AttributeError):
            raise Rejected("garbled") from None
        kind = type(msg).__name__
        try:
            if kind == "RMC":
                if msg.status != "A":
                    raise Rejected("no_fix")
                state["date"] = msg.datestamp
                day = msg.datestamp
            elif kind == "GGA":
                if int(msg.gps_qual or 0) == 0:
                    raise Rejected("no_fix")
                day = state["date"] or datetime.fromtimestamp(
                    recv_ns / 1e9, timezone.utc).date()
            else:
                raise Rejected("other_sentence")
            lat, lon, hms = msg.latitude, msg.longitude, msg.timestamp
        except Rejected:
            raise
        except (ValueError, TypeError, AttributeError):  # a field pynmea2 cannot read
            raise Rejected("garbled") from None
        if hms is None or not (-90 <= lat <= 90 and -180 <= lon <= 180):
            raise Rejected("garbled")
        dt = datetime.combine(day, hms).replace(tzinfo=timezone.utc)
        t = int(dt.timestamp()) * 10**9 + dt.microsecond * 1000
        if t == state["t"]:
            raise Rejected("repeat_fix")
        state["t"] = t
        return t, [float(lat), float(lon)], "instrument"

    return parse


def parser(cfg: SourceConfig) -> Callable[[str, int], Sample]:
    return {"delimited": delimited, "csv": csv_header, "nmea": nmea}[cfg.format](cfg)


def bulk_parser(cfg: SourceConfig) -> Callable[[list[bytes], int], Samples | None] | None:
    """The bulk parser of a source's format (module docstring), or None."""
    return delimited_bulk(cfg) if cfg.format == "delimited" else None
