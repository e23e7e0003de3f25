"""Read a CSV of measurements into sensor series, reporting every bad row.

Format: a header row, then one row per time stamp.

* Time column (exactly one): ``time_s`` = seconds (decimal, parsed exactly to ns) since the
  ``start`` instant (default 2000-01-01T00:00:00Z, so relative times start at a real date), or
  ``time`` = ISO 8601 date-time (``2024-03-01T12:00:00.05Z``; up to 9 fractional digits; a time
  without offset is UTC).
* Channel columns ``<field>`` exactly as in :data:`monitor.blocks.SENSOR_FIELDS`, i.e.
  ``<channel>_<unit>``: ``tension_N``; ``heave_m, surge_m, sway_m`` (motion);
  ``accel_x_mps2, accel_y_mps2, accel_z_mps2`` (imu); ``lat_deg, lon_deg`` (gnss);
  ``hs_m, tp_s`` (waves). A sensor needs all of its columns. Any other column is an error
  (a wrong unit such as ``tension_kN`` is named as such), never silently ignored.

Irregular sampling is kept as is. A row is skipped, and reported with its line number and the
reason, when it has the wrong number of cells, an empty cell, a number that does not parse, a
NaN or infinite value, a bad time, or a time equal to (duplicate) or before (backwards) the
last accepted row. Blank lines are ignored and counted. Nothing is converted or guessed.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from datetime import datetime, timezone
from decimal import Decimal
from pathlib import Path

import numpy as np

from monitor.blocks import SENSOR_FIELDS

DEFAULT_START = "2000-01-01T00:00:00Z"
_FIELD_SENSOR = {f: s for s, fields in SENSOR_FIELDS.items() for f in fields}
_ISO = re.compile(
    r"^(\d{4}-\d\d-\d\d[T ]\d\d:\d\d(?::\d\d)?)(?:\.(\d+))?(Z|z|[+-]\d\d:?\d\d)?$"
)
_NS = Decimal(10**9)
# a plain decimal number: Python's float() and Decimal() would also take "1_000" or "١٢"
_NUMBER = re.compile(r"^[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?$", re.ASCII)
_NON_FINITE = re.compile(r"^[+-]?(?:nan|inf|infinity)$", re.IGNORECASE)
LAST_NS = 2**63 - 1  # time stamps are int64 ns since the epoch: 2262-04-11T23:47:16Z at most


@dataclass(frozen=True)
class BadRow:
    """A skipped row: 1-based line number in the file and why."""

    line: int
    reason: str

    def __str__(self) -> str:
        return f"line {self.line}: {self.reason}"


@dataclass
class CsvData:
    """What was read: one (t_ns, values) pair per sensor present, plus the row accounting."""

    sensors: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    rows_read: int = 0
    rows_accepted: int = 0
    blank_lines: int = 0
    bad_rows: list[BadRow] = field(default_factory=list)

    @property
    def rows_skipped(self) -> int:
        return len(self.bad_rows)

    def summary(self) -> str:
        lines = [f"rows read {self.rows_read}, accepted {self.rows_accepted}, "
                 f"skipped {self.rows_skipped}, blank lines ignored {self.blank_lines}"]
        for sensor, (t, _) in self.sensors.items():
            if t.shape[0]:
                lines.append(f"{sensor}: {t.shape[0]} samples, "
                             f"{_iso(int(t[0]))} .. {_iso(int(t[-1]))}")
        return "\n".join(lines)


def _iso(t_ns: int) -> str:
    s, ns = divmod(t_ns, 10**9)
    return datetime.fromtimestamp(s, timezone.utc).strftime("%Y-%m-%dT%H:%M:%S") + f".{ns:09d}Z"


def parse_iso_ns(text: str) -> int:
    """ISO 8601 date-time to ns since the epoch, exactly; ValueError naming the text."""
    m = _ISO.match(text.strip())
    if m is None:
        raise ValueError(f"bad time {text!r}: expected ISO 8601 like 2024-03-01T12:00:00.05Z")
    base, frac, tz = m.groups()
    if frac is not None and len(frac) > 9:
        raise ValueError(f"bad time {text!r}: more than 9 fractional digits")
    tz = "+00:00" if tz in (None, "Z", "z") else tz
    try:
        dt = datetime.fromisoformat(base.replace(" ", "T") + tz)
    except ValueError as e:
        raise ValueError(f"bad time {text!r}: {e}") from None
    secs = int(dt.timestamp())
    t = secs * 10**9 + (int(frac.ljust(9, "0")) if frac else 0)
    if t > LAST_NS:
        raise ValueError(f"bad time {text!r}: after {_iso(LAST_NS)}, the last nanosecond time "
                         "stamp")
    return t


def _columns(header: list[str]) -> tuple[int, bool, dict[str, list[int]]]:
    """Index of the time column, whether it is ``time_s``, and sensor -> value column indices."""
    names = [h.strip() for h in header]
    other = [sep for sep in (";", "\t", "|") if len(names) == 1 and sep in names[0]]
    if other:
        raise ValueError(f"CSV header {names[0]!r}: one column; the file looks "
                         f"{other[0]!r}-separated, the columns must be separated by commas")
    times = [i for i, n in enumerate(names) if n in ("time_s", "time")]
    if len(times) != 1:
        raise ValueError(f"CSV header {names}: needs exactly one time column, 'time_s' or 'time'")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"CSV header: duplicate columns {dup}")
    sensors: dict[str, dict[str, int]] = {}
    for i, n in enumerate(names):
        if i == times[0]:
            continue
        if n not in _FIELD_SENSOR:
            stem = n.rsplit("_", 1)[0] if "_" in n else n
            hint = [f for f in _FIELD_SENSOR if f.startswith(stem + "_")]
            why = (f"wrong unit, expected {hint[0]!r}" if hint else
                   f"expected <channel>_<unit> among {sorted(_FIELD_SENSOR)}")
            raise ValueError(f"CSV column {n!r} (column {i + 1}): {why}")
        sensors.setdefault(_FIELD_SENSOR[n], {})[n] = i
    if not sensors:
        raise ValueError("CSV header has no channel column (e.g. tension_N)")
    out = {}
    for sensor, cols in sensors.items():
        missing = [f for f in SENSOR_FIELDS[sensor] if f not in cols]
        if missing:
            raise ValueError(f"CSV columns {sorted(cols)} present but {missing} missing: "
                             f"{sensor} needs all of {list(SENSOR_FIELDS[sensor])}")
        out[sensor] = [cols[f] for f in SENSOR_FIELDS[sensor]]
    return times[0], names[times[0]] == "time_s", out


def read_csv(path: str | Path, start: str = DEFAULT_START) -> CsvData:
    """Parse a measurement CSV (see module doc). ValueError for an unusable header/start."""
    try:
        return _read_csv(path, parse_iso_ns(start))
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte {exc.object[exc.start]:#04x}); expected "
                         "a CSV file") from None


def _read_csv(path: str | Path, start_ns: int) -> CsvData:
    data = CsvData()
    with open(path, newline="", encoding="utf-8-sig") as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None:
            raise ValueError(f"{path}: empty file, expected a header row")
        t_col, relative, sensors = _columns(header)
        names = [h.strip() for h in header]
        width = len(header)
        times: list[int] = []
        rows: list[list[float]] = []
        value_cols = sorted(i for cols in sensors.values() for i in cols)
        last = None
        for row in reader:
            line = reader.line_num
            if not row or all(not c.strip() for c in row) and len(row) <= 1:
                data.blank_lines += 1
                continue
            data.rows_read += 1
            bad = _bad_cells(row, width, value_cols, names)
            if bad:
                data.bad_rows.append(BadRow(line, bad))
                continue
            try:
                t = _time_ns(row[t_col].strip(), relative, start_ns)
            except ValueError as e:
                data.bad_rows.append(BadRow(line, str(e)))
                continue
            if last is not None and t <= last:
                why = "duplicate time" if t == last else "time going backwards"
                data.bad_rows.append(BadRow(line, f"{why}: {row[t_col].strip()} after the "
                                                  f"previous accepted row's {_iso(last)}"))
                continue
            last = t
            times.append(t)
            rows.append([float(row[i]) for i in value_cols])
    data.rows_accepted = len(times)
    t_arr = np.array(times, np.int64)
    v_all = np.array(rows, np.float64).reshape(len(rows), len(value_cols)).T
    where = {c: k for k, c in enumerate(value_cols)}
    for sensor, cols in sensors.items():
        data.sensors[sensor] = (t_arr, np.ascontiguousarray(v_all[[where[c] for c in cols]]))
    return data


def _bad_cells(row: list[str], width: int, value_cols: list[int], names: list[str]) -> str | None:
    if len(row) != width:
        return f"wrong column count: {len(row)} cells, header has {width}"
    for i in value_cols:
        cell = row[i].strip()
        if not cell:
            return f"empty cell in column {names[i]}"
        if not _is_number(cell):
            return f"unparsable number in column {names[i]}: {cell!r}"
        v = float(cell)
        if v != v:
            return f"NaN in column {names[i]}"
        if v in (float("inf"), float("-inf")):
            return f"infinite value in column {names[i]}: {cell!r}"
    return None


def _is_number(cell: str) -> bool:
    """A plain decimal number, or a spelling of NaN/inf (rejected later, with its reason)."""
    return bool(_NUMBER.match(cell) or _NON_FINITE.match(cell))


def _time_ns(cell: str, relative: bool, start_ns: int) -> int:
    if not cell:
        raise ValueError("empty time cell")
    if not relative:
        t = parse_iso_ns(cell)  # checks the int64 range itself
    else:
        if not _is_number(cell):
            raise ValueError(f"bad time_s {cell!r}: not a number")
        d = Decimal(cell)
        if not d.is_finite():
            raise ValueError(f"bad time_s {cell!r}: not finite")
        t = start_ns + int((d * _NS).to_integral_value())
        if t > LAST_NS:
            raise ValueError(f"bad time_s {cell!r}: after {_iso(LAST_NS)}, the last nanosecond "
                             "time stamp")
    if t <= 0:
        raise ValueError(f"bad time {cell!r}: not after the Unix epoch (1970-01-01T00:00:00Z)")
    return t
