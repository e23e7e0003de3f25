"""The bridge's configuration: ``[buoy] id``, ``[bridge]`` and ``[[source]]`` tables.

Declared as msgspec Structs and parsed by :func:`monitor.schema.parse_struct`, so errors name
the key and the value, as every configuration error of the product does.
"""

from __future__ import annotations

import math
from datetime import datetime
from pathlib import Path
from typing import Annotated, Any, Literal, Mapping

import msgspec
from msgspec import Meta

from monitor.blocks import SENSOR_FIELDS, validate_buoy_id
from monitor.daemon_config import check_endpoints
from monitor.quanta import quanta as sensor_quanta
from monitor.schema import ConfigError, Errors, error, parse_struct, read_toml

Positive = Annotated[float, Meta(gt=0)]
NonEmpty = Annotated[str, Meta(min_length=1)]
_SAMPLE_TIME = datetime(2018, 11, 30, 9, 58, 27, 538000)  # a time_format must read its own output
# the key a transport cannot do without
_NEEDS = {"serial": "device", "tcp_client": "port", "tcp_server": "port", "udp": "port",
          "file": "path", "stdin": None}


class SourceConfig(msgspec.Struct, frozen=True):
    """One instrument: where its bytes come from, how a line reads, which stream it feeds."""

    name: NonEmpty
    sensor: Annotated[str, Meta(description=f"one of {list(SENSOR_FIELDS)}")]
    transport: Literal["serial", "tcp_client", "tcp_server", "udp", "file", "stdin"]
    format: Literal["delimited", "nmea", "csv"] = "delimited"  # default "nmea" for gnss
    device: str = ""
    baud: Annotated[int, Meta(ge=50, le=4_000_000)] = 9600
    parity: Literal["N", "E", "O", "M", "S"] = "N"
    host: str = "127.0.0.1"
    port: Annotated[int, Meta(ge=1, le=65535)] = 0  # 0: the transport takes no port
    path: str = ""
    from_start: bool = True
    separator: str = ","
    columns: Annotated[dict[str, Annotated[int, Meta(ge=0)]], Meta(
        description="a table of field = column number (>= 0)")] = msgspec.field(
            default_factory=dict)
    scale: Annotated[dict[str, float], Meta(description="a table of field = number")
                     ] = msgspec.field(default_factory=dict)
    offset: Annotated[dict[str, float], Meta(description="a table of field = number")
                      ] = msgspec.field(default_factory=dict)
    time_column: Annotated[int, Meta(ge=0)] | None = None
    time_format: str = "unix"  # "unix" seconds, or a datetime.strptime format (UTC)
    block_s: Positive = 1.0
    reconnect_s: Positive = 2.0
    stall_s: Positive = 5.0  # no line for this long (or not connected): the source is down

    def check(self, where: str, raw: Mapping[str, Any]) -> "SourceConfig":
        """The sensor's fields in columns, scale and offset (filled in); what the transport
        needs; NMEA for GNSS only."""
        if self.sensor not in SENSOR_FIELDS:
            raise error(where, "sensor", self.sensor, f"must be one of {list(SENSOR_FIELDS)}")
        fields = SENSOR_FIELDS[self.sensor]
        fmt = self.format if "format" in raw or self.sensor != "gnss" else "nmea"
        if fmt == "nmea" and self.sensor != "gnss":
            raise error(where, "format", fmt, "NMEA 0183 sentences feed the gnss stream only")
        if fmt == "delimited" and set(self.columns) != set(fields):
            raise error(where, "columns", self.columns,
                        f"must map every field of {self.sensor} ({list(fields)}) to a column number")
        maps = {}
        for key, default in (("scale", 1.0), ("offset", 0.0)):
            given = getattr(self, key)
            if any(f not in fields for f in given):
                raise error(where, key, given,
                            f"must map fields of {self.sensor} ({list(fields)}) to numbers")
            maps[key] = {f: float(given.get(f, default)) for f in fields}
            # a NaN, infinite or zero scale turns every line into NaN or a constant
            if not all(math.isfinite(v) and (v != 0 or key == "offset")
                       for v in maps[key].values()):
                raise error(where, key, given, "must map fields to finite numbers"
                            + (", not 0" if key == "scale" else ""))
        if self.time_format != "unix":
            try:  # a bad directive would reject every line as bad_time, one by one
                datetime.strptime(_SAMPLE_TIME.strftime(self.time_format), self.time_format)
            except ValueError as exc:
                raise error(where, "time_format", self.time_format,
                            f"not a strptime format ({exc})") from None
        need = _NEEDS[self.transport]
        if need is not None and need not in raw:
            raise error(where, need, None, f"is required with transport = {self.transport!r}")
        return msgspec.structs.replace(self, format=fmt, port=self.port if need == "port" else 0,
                                       **maps)

    @property
    def timed_at_read(self) -> bool:
        """Its samples take the time of the read (a delimited line without a time column)."""
        return self.format == "delimited" and self.time_column is None


class BridgeSection(msgspec.Struct, frozen=True):
    """``[bridge]``: where to publish, how often to report, what the cache holds."""

    connect: Annotated[tuple[str, ...], Meta(
        min_length=1, description="a non-empty list of Zenoh endpoints")] = ("tcp/127.0.0.1:7447",)
    status_interval_s: Positive = 1.0
    cache_blocks: Annotated[int, Meta(ge=1, le=10_000_000)] = 3600  # blocks per stream
    quanta: Annotated[dict[str, Any], Meta(description="a table of field = quantum")
                      ] = msgspec.field(default_factory=dict)  # field -> quantum on the wire

    def check(self, where: str, raw: Mapping[str, Any]) -> "BridgeSection":
        check_endpoints(where, "connect", self.connect)
        try:
            for sensor in SENSOR_FIELDS:
                sensor_quanta(sensor, self.quanta)
        except (ValueError, TypeError) as exc:
            raise error(where, "quanta", self.quanta, str(exc)) from None
        return self


class BridgeConfig(msgspec.Struct, frozen=True):
    """What a bridge runs: the buoy, its ``[bridge]`` settings and its sources."""

    buoy_id: str
    connect: tuple[str, ...]
    sources: tuple[SourceConfig, ...]
    status_interval_s: float = 1.0
    cache_blocks: int = 3600
    quanta: Mapping[str, float] = msgspec.field(default_factory=dict)


def parse_sources(sources: Any) -> tuple[SourceConfig, ...]:
    """The ``[[source]]`` tables (at least one; unique names)."""
    if not isinstance(sources, list) or not sources:
        raise error("", "source", sources, "at least one [[source]] is required")
    errors = Errors()  # every source's errors at once
    found = [errors.parse(parse_struct, SourceConfig, s, f"source[{i}]")
             for i, s in enumerate(sources)]
    errors.raise_any()
    parsed = tuple(s for s in found if s is not None)
    names = [s.name for s in parsed]
    for n in names:
        if names.count(n) > 1:
            raise error("", "source.name", n, "must be unique")
    return parsed


def parse_bridge_config(raw: Mapping[str, Any]) -> BridgeConfig:
    """The bridge's sections of a parsed TOML document: ``[buoy] id``, ``[bridge]``,
    ``[[source]]`` (the same in a bridge's own file and in the daemon's)."""
    errors = Errors()  # the errors of [buoy], [bridge] and every [[source]] at once
    buoy_id = errors.parse(_buoy_id, raw.get("buoy", {}))
    b = errors.parse(parse_struct, BridgeSection, raw.get("bridge"), "bridge")
    sources = errors.parse(parse_sources, raw.get("source", []))
    errors.raise_any()
    assert buoy_id is not None and b is not None and sources is not None  # else raised
    return BridgeConfig(buoy_id, b.connect, sources, b.status_interval_s, b.cache_blocks,
                        b.quanta)


def _buoy_id(buoy: Any) -> str:
    if not isinstance(buoy, Mapping) or "id" not in buoy:
        # worded as [buoy]'s own parse says it, so a daemon's file with sources says it once
        raise ConfigError("config error: buoy.id is missing")
    try:
        return validate_buoy_id(buoy["id"])
    except ValueError as exc:
        raise error("", "buoy.id", buoy["id"], str(exc)) from None


def load_bridge_config(path: str | Path) -> BridgeConfig:
    return parse_bridge_config(read_toml(path))
