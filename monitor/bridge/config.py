"""The bridge's configuration: ``[buoy] id``, ``[bridge]`` and ``[[source]]`` tables.

Errors name the key and the value, as every configuration error of the product does.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from monitor.blocks import SENSOR_FIELDS, validate_buoy_id
from monitor.config import ConfigError
from monitor.quanta import quanta as sensor_quanta

TRANSPORTS = ("serial", "tcp_client", "tcp_server", "udp", "file", "stdin")
FORMATS = ("delimited", "nmea", "csv")
PARITIES = ("N", "E", "O", "M", "S")


@dataclass(frozen=True)
class SourceConfig:
    """One instrument: where its bytes come from, how a line reads, which stream it feeds."""

    name: str
    sensor: str
    transport: str
    format: str
    device: str = ""
    baud: int = 9600
    parity: str = "N"
    host: str = "127.0.0.1"
    port: int = 0
    path: str = ""
    from_start: bool = True
    separator: str = ","
    columns: Mapping[str, int] = field(default_factory=dict)
    scale: Mapping[str, float] = field(default_factory=dict)
    offset: Mapping[str, float] = field(default_factory=dict)
    time_column: int | None = None
    time_format: str = "unix"  # "unix" seconds, or a datetime.strptime format (UTC)
    block_s: float = 1.0
    reconnect_s: float = 2.0
    stall_s: float = 5.0  # no line for this long (or not connected): the source is down

    @property
    def timed_at_read(self) -> bool:
        """Its samples take the time of the read (a delimited line without a time column)."""
        return self.format == "delimited" and self.time_column is None


@dataclass(frozen=True)
class BridgeConfig:
    buoy_id: str
    connect: tuple[str, ...]
    sources: tuple[SourceConfig, ...]
    status_interval_s: float = 1.0
    cache_blocks: int = 3600
    quanta: Mapping[str, float] = field(default_factory=dict)  # field -> quantum on the wire


def _err(key: str, value: Any, why: str) -> ConfigError:
    return ConfigError(f"config error: {key} = {value!r}: {why}")


def _num(where: str, d: Mapping[str, Any], key: str, default: float, low: float = 0.0) -> float:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= low:
        raise _err(f"{where}.{key}", v, f"must be a number > {low:g}")
    return float(v)


def _int(where: str, d: Mapping[str, Any], key: str, default: int, low: int, high: int) -> int:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
        raise _err(f"{where}.{key}", v, f"must be an integer {low}-{high}")
    return v


def _str(where: str, d: Mapping[str, Any], key: str, default: str | None = None,
         choices: tuple[str, ...] | None = None) -> str:
    v = d.get(key, default)
    if not isinstance(v, str) or (default is None and not v):
        raise _err(f"{where}.{key}", v, "must be a non-empty string" if v is None or
                   isinstance(v, str) else "must be a string")
    if choices is not None and v not in choices:
        raise _err(f"{where}.{key}", v, f"must be one of {list(choices)}")
    return v


def _source(where: str, d: Any) -> SourceConfig:
    if not isinstance(d, Mapping):
        raise _err(where, d, "must be a table ([[source]])")
    allowed = set(SourceConfig.__dataclass_fields__)
    for k in d:
        if k not in allowed:
            raise _err(f"{where}.{k}", d[k], f"unknown key; expected one of {sorted(allowed)}")
    name = _str(where, d, "name")
    sensor = _str(where, d, "sensor", choices=tuple(SENSOR_FIELDS))
    transport = _str(where, d, "transport", choices=TRANSPORTS)
    fmt = _str(where, d, "format", "nmea" if sensor == "gnss" else "delimited", FORMATS)
    if fmt == "nmea" and sensor != "gnss":
        raise _err(f"{where}.format", fmt, "NMEA 0183 sentences feed the gnss stream only")
    fields = SENSOR_FIELDS[sensor]
    columns = d.get("columns", {})
    if fmt == "delimited":
        if not isinstance(columns, Mapping) or set(columns) != set(fields):
            raise _err(f"{where}.columns", columns,
                       f"must map every field of {sensor} ({list(fields)}) to a column number")
        for f, c in columns.items():
            if isinstance(c, bool) or not isinstance(c, int) or c < 0:
                raise _err(f"{where}.columns.{f}", c, "must be a column number >= 0")
    maps = {}
    for key, default in (("scale", 1.0), ("offset", 0.0)):
        m = d.get(key, {})
        if not isinstance(m, Mapping) or any(k not in fields for k in m):
            raise _err(f"{where}.{key}", m, f"must map fields of {sensor} ({list(fields)}) to numbers")
        for f, v in m.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise _err(f"{where}.{key}.{f}", v, "must be a finite number")
        maps[key] = {f: float(m.get(f, default)) for f in fields}
    tc = d.get("time_column")
    if tc is not None and (isinstance(tc, bool) or not isinstance(tc, int) or tc < 0):
        raise _err(f"{where}.time_column", tc, "must be a column number >= 0")
    needs = {"serial": ("device",), "tcp_client": ("port",), "tcp_server": ("port",),
             "udp": ("port",), "file": ("path",), "stdin": ()}[transport]
    for k in needs:
        if k not in d:
            raise _err(f"{where}.{k}", None, f"is required with transport = {transport!r}")
    from_start = d.get("from_start", True)
    if not isinstance(from_start, bool):
        raise _err(f"{where}.from_start", from_start, "must be true or false")
    return SourceConfig(
        name=name, sensor=sensor, transport=transport, format=fmt,
        device=_str(where, d, "device", ""), baud=_int(where, d, "baud", 9600, 50, 4_000_000),
        parity=_str(where, d, "parity", "N", PARITIES), host=_str(where, d, "host", "127.0.0.1"),
        port=_int(where, d, "port", 0, 0 if transport == "stdin" else 1, 65535) if needs
        and "port" in needs else 0,
        path=_str(where, d, "path", ""), from_start=from_start,
        separator=_str(where, d, "separator", ","), columns=dict(columns),
        scale=maps["scale"], offset=maps["offset"], time_column=tc,
        time_format=_str(where, d, "time_format", "unix"),
        block_s=_num(where, d, "block_s", 1.0), reconnect_s=_num(where, d, "reconnect_s", 2.0),
        stall_s=_num(where, d, "stall_s", 5.0),
    )


_BRIDGE_KEYS = ("connect", "status_interval_s", "cache_blocks", "quanta")


def parse_bridge_section(b: Any) -> tuple[tuple[str, ...], float, int, dict[str, float]]:
    """``[bridge]``: (connect endpoints, status interval, cache blocks per stream, quanta of
    the fields on the wire)."""
    if not isinstance(b, Mapping):
        raise _err("bridge", b, "must be a table")
    for k in b:
        if k not in _BRIDGE_KEYS:
            raise _err(f"bridge.{k}", b[k], f"unknown key; expected one of {list(_BRIDGE_KEYS)}")
    connect = b.get("connect", ["tcp/127.0.0.1:7447"])
    if not isinstance(connect, list) or not connect or not all(isinstance(e, str) for e in connect):
        raise _err("bridge.connect", connect, "must be a non-empty list of Zenoh endpoints")
    quanta = b.get("quanta", {})
    try:
        if not isinstance(quanta, Mapping):
            raise ValueError("must be a table of field = quantum")
        for sensor in SENSOR_FIELDS:
            sensor_quanta(sensor, quanta)
    except (ValueError, TypeError) as exc:
        raise _err("bridge.quanta", quanta, str(exc)) from None
    return (tuple(connect), _num("bridge", b, "status_interval_s", 1.0),
            _int("bridge", b, "cache_blocks", 3600, 1, 10_000_000), dict(quanta))


def parse_sources(sources: Any) -> tuple[SourceConfig, ...]:
    """The ``[[source]]`` tables (at least one; unique names)."""
    if not isinstance(sources, list) or not sources:
        raise _err("source", sources, "at least one [[source]] is required")
    parsed = tuple(_source(f"source[{i}]", s) for i, s in enumerate(sources))
    names = [s.name for s in parsed]
    for n in names:
        if names.count(n) > 1:
            raise _err("source.name", n, "must be unique")
    return parsed


def parse_bridge_config(raw: Mapping[str, Any]) -> BridgeConfig:
    """The bridge's sections of a parsed TOML document: ``[buoy] id``, ``[bridge]``,
    ``[[source]]`` (the same in a bridge's own file and in the daemon's)."""
    buoy = raw.get("buoy", {})
    if not isinstance(buoy, Mapping) or "id" not in buoy:
        raise _err("buoy.id", None, "is required")
    try:
        buoy_id = validate_buoy_id(buoy["id"])
    except ValueError as exc:
        raise _err("buoy.id", buoy["id"], str(exc)) from None
    connect, interval, cache, quanta = parse_bridge_section(raw.get("bridge", {}))
    return BridgeConfig(buoy_id, connect, parse_sources(raw.get("source", [])), interval, cache,
                        quanta)


def load_bridge_config(path: str | Path) -> BridgeConfig:
    try:
        raw = tomllib.loads(Path(path).read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config error: {path}: {exc}") from None
    return parse_bridge_config(raw)
