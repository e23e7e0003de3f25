"""Instrument lines -> timed samples: NMEA 0183 GNSS, configurable delimited lines, CSV.

Each parser takes one decoded line and the logger's receive time (ns) and returns
``(t_ns, values, time_source)``: the values in the order of the stream's fields
(:data:`monitor.blocks.SENSOR_FIELDS`), ``time_source`` ``"instrument"`` or ``"receive"``;
or raises :class:`Rejected` with a short reason (the counter's name).
"""

from __future__ import annotations

import math
import re
from datetime import datetime, timezone
from typing import Any, Callable

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


def instrument_time(text: str, fmt: str) -> int:
    """Sensor time (ns since the epoch, UTC) from a time cell: ``unix`` seconds, or a
    ``strptime`` format (a time without offset is UTC)."""
    text = text.strip()
    if fmt == "unix":  # exact to the ns (a float would not be); before 1970 is no real time
        m = _UNIX.fullmatch(text)
        if m is None:
            raise Rejected("bad_time")
        return int(m[1]) * 1_000_000_000 + int(((m[2] or "") + "000000000")[:9])
    try:
        dt = datetime.strptime(text, fmt)
    except ValueError:
        raise Rejected("bad_time") from None
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=timezone.utc)
    return (int(dt.timestamp()) * 10**9) + dt.microsecond * 1000


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
