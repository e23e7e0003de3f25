"""Sea-state time series from files: forecasts and hindcasts of Hs, Tp (and direction).

Three text formats, told apart by their first line:

* CSV with a header naming ``time`` (ISO 8601) or ``time_s`` (Unix seconds), ``hs_m``,
  ``tp_s`` and optionally ``direction_deg``;
* NDBC standard meteorological text (header ``#YY  MM DD hh mm WDIR ... WVHT DPD APD MWD``;
  ``WVHT`` = Hs, ``DPD`` = dominant (peak) period, ``MWD`` = direction; 99/999 = missing);
* the semicolon-separated ``YYYY-MM-DD-HH; Hs; Tz`` of the ECWorkshop benchmark data
  (hourly NDBC records with the zero-crossing period, converted to Tp with the JONSWAP
  ratio Tz / Tp = 0.7782, ``models.environment.TZ_OVER_TP_JONSWAP``).

Rows with a missing or impossible value (not finite, Hs < 0, Tp <= 0) are skipped and
counted; times must increase (a row at or before the previous time is skipped and counted).
"""

from __future__ import annotations

import csv
import math
from collections import Counter
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from models.environment import TZ_OVER_TP_JONSWAP
from models.sea_state_table import step_hours


@dataclass(frozen=True)
class SeaStates:
    """Sea states at times ``t_s`` (Unix seconds, increasing); ``skipped`` counts the rows
    left out by reason."""

    t_s: NDArray[np.float64]
    hs_m: NDArray[np.float64]
    tp_s: NDArray[np.float64]
    direction_deg: NDArray[np.float64]
    skipped: Counter = field(default_factory=Counter)

    def __len__(self) -> int:
        return int(self.t_s.size)

    def step_hours(self) -> NDArray[np.float64]:
        """How long each row lasts (:func:`models.sea_state_table.step_hours`)."""
        return step_hours(self.t_s)


def read_sea_states(path: str | Path) -> SeaStates:
    """Read a sea-state file in any of the module's formats (ValueError if none fits)."""
    p = Path(path)
    try:
        with p.open(newline="") as fh:
            first = fh.readline()
            fh.seek(0)
            if first.lstrip().startswith("#YY") or first.startswith("YY "):
                rows, skipped = _ndbc(fh)
            elif first.lower().startswith("time (yyyy-mm-dd-hh)"):
                rows, skipped = _benchmark(fh)
            elif "hs_m" in first and "tp_s" in first:
                rows, skipped = _csv(fh)
            else:
                raise ValueError(f"{p}: not a sea-state file (expected a CSV header with "
                                 "time, hs_m, tp_s; an NDBC '#YY MM DD hh mm ... WVHT DPD' "
                                 "header; or 'time (YYYY-MM-DD-HH); significant wave height "
                                 "(m); zero-up-crossing period (s)')")
    except UnicodeDecodeError as exc:  # a binary file: say which, not just the codec's words
        raise ValueError(f"{p}: not a text file ({exc})") from None
    return _assemble(rows, skipped, p)


def _assemble(rows: list[tuple[float, float, float, float]], skipped: Counter,
              p: Path) -> SeaStates:
    kept: list[tuple[float, float, float, float]] = []
    for r in rows:
        t, hs, tp, _ = r
        if not (math.isfinite(hs) and math.isfinite(tp) and hs >= 0 and tp > 0):
            skipped["missing or impossible Hs/Tp"] += 1
        elif kept and t <= kept[-1][0]:
            skipped["time not increasing"] += 1
        else:
            kept.append(r)
    if not kept:
        raise ValueError(f"{p}: no usable sea state (skipped: {dict(skipped)})")
    a = np.array(kept, dtype=float)
    return SeaStates(a[:, 0], a[:, 1], a[:, 2], a[:, 3], skipped)


def _utc(*parts: int) -> float:
    return datetime(*parts, tzinfo=timezone.utc).timestamp()


def _num(s: str, missing: tuple[float, ...] = ()) -> float:
    try:
        v = float(s)
    except ValueError:
        return math.nan
    return math.nan if v in missing else v


def _ndbc(fh) -> tuple[list, Counter]:
    header = fh.readline().lstrip("#").split()
    col = {name: i for i, name in enumerate(header)}
    for need in ("YY", "MM", "DD", "hh", "WVHT", "DPD"):
        if need not in col:
            raise ValueError(f"NDBC text without a {need} column")
    rows, skipped = [], Counter()
    for line in fh:
        f = line.split()
        if not f or line.startswith("#"):
            continue
        try:
            year = int(f[col["YY"]])
            year += 1900 if year < 100 else 0
            t = _utc(year, int(f[col["MM"]]), int(f[col["DD"]]), int(f[col["hh"]]),
                     int(f[col["mm"]]) if "mm" in col else 0)
        except (ValueError, IndexError):
            skipped["bad time"] += 1
            continue
        direction = _num(f[col["MWD"]], (999.0,)) if "MWD" in col else math.nan
        rows.append((t, _num(f[col["WVHT"]], (99.0,)), _num(f[col["DPD"]], (99.0,)), direction))
    return rows, skipped


def _benchmark(fh) -> tuple[list, Counter]:
    fh.readline()
    rows, skipped = [], Counter()
    for line in fh:
        f = [x.strip() for x in line.split(";")]
        if len(f) < 3:
            if line.strip():
                skipped["wrong column count"] += 1
            continue
        try:
            y, mo, d, h = (int(x) for x in f[0].split("-"))
            t = _utc(y, mo, d, h)
        except ValueError:
            skipped["bad time"] += 1
            continue
        rows.append((t, _num(f[1]), _num(f[2]) / TZ_OVER_TP_JONSWAP, math.nan))
    return rows, skipped


def _csv(fh) -> tuple[list, Counter]:
    reader = csv.DictReader(fh)
    fields = reader.fieldnames or []
    if "time" not in fields and "time_s" not in fields:
        raise ValueError("sea-state CSV needs a time (ISO 8601) or time_s column")
    rows, skipped = [], Counter()
    for rec in reader:
        try:
            if "time_s" in fields:
                t = float(rec["time_s"])
            else:
                t = datetime.fromisoformat(rec["time"].replace("Z", "+00:00")).timestamp()
        except (ValueError, TypeError, AttributeError):
            skipped["bad time"] += 1
            continue
        direction = _num(rec.get("direction_deg") or "")
        rows.append((t, _num(rec["hs_m"] or ""), _num(rec["tp_s"] or ""), direction))
    return rows, skipped
