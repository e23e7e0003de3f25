"""Configuration sections of the live daemon: ``[zenoh]``, ``[state]``, ``[record]``, ``[health]``.

Each section is declared as a frozen ``msgspec.Struct`` and parsed by
:func:`monitor.schema.parse_struct`; errors name the bad key and value, e.g.
``config error: zenoh.mode = 'router': must be one of ['client', 'peer']``.
:func:`parse_daemon_sections` reads them all from a whole-file TOML mapping (missing
sections take their defaults).

Example::

    [zenoh]
    mode = "peer"                      # embedded peer, no router needed; or "client"
    listen = ["tcp/127.0.0.1:7447"]    # loopback only by default
    connect = []                       # e.g. ["tcp/10.0.0.2:7447"] (required in client mode)
    multicast_scouting = false
    status_interval_s = 1.0            # status publication period (<= 1 s)
    [zenoh.tls]                        # optional; used by tls/ and quic/ endpoints
    root_ca_certificate = "/etc/buoymon/ca.pem"
    listen_certificate = "/etc/buoymon/cert.pem"
    listen_private_key = "/etc/buoymon/key.pem"
    [zenoh.auth]                       # optional user/password authentication
    user = "buoy"
    password = "secret"                # or dictionary_file = "/etc/buoymon/users.txt"

    [state]
    path = "/var/lib/buoymon/state.sqlite"
    checkpoint_interval_s = 10.0

    [record]
    enabled = true
    dir = "/var/lib/buoymon/record"
    rotate_s = 3600
    flush_interval_s = 5.0

    [health]
    data_age_timeout_s = { tension = 5.0, imu = 5.0, gnss = 10.0, waves = 3600.0 }
    live_rules = true                  # wall-clock alert rules (monitor.alerts.live)
    required_streams = []              # alert on these even if never seen
    fatigue_blind_timeout_s = 60.0
    clock_skew_max_s = 600.0
    time_restart_min_s = 1.0
    hold_s = 600.0

    [metrics]
    enabled = true
    listen = "127.0.0.1"
    port = 9464                        # 0: any free port (logged, and in the status)
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal, Mapping

import msgspec
from msgspec import Meta

from monitor.blocks import SENSOR_FIELDS
from monitor.schema import Errors, error, parse_struct

_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws|unixsock-stream)/\S+$")
# the port of an IP endpoint (before zenoh's optional "#" metadata)
_PORT = re.compile(r"^(?:tcp|udp|tls|quic|ws)/.*:(\d+)(?:#.*)?$")

Positive = Annotated[float, Meta(gt=0)]
NonEmpty = Annotated[str, Meta(min_length=1)]
Endpoints = Annotated[tuple[str, ...], Meta(
    description="a list of endpoint strings like 'tcp/127.0.0.1:7447'")]


def check_endpoints(where: str, key: str, endpoints: tuple[str, ...]) -> None:
    """Config error naming ``where.key`` unless every endpoint is '<proto>/<address>' with a
    port (if any) that zenoh takes: it refuses others only when the session opens."""
    for e in endpoints:
        if not _ENDPOINT.match(e):
            raise error(where, key, list(endpoints),
                        f"endpoint {e!r} is not of the form '<proto>/<address>'")
        port = _PORT.search(e)
        if port is not None and int(port.group(1)) > 65535:
            raise error(where, key, list(endpoints),
                        f"endpoint {e!r}: port {port.group(1)} is not in 0..65535")


def _pair(where: str, given: Mapping[str, Any], a: str, b: str) -> None:
    """Keys ``a`` and ``b`` must be given together."""
    if (a in given) != (b in given):
        raise error(where, a if b in given else b, None, f"{a} and {b} must be given together")


class TlsConfig(msgspec.Struct, frozen=True):
    """File paths for zenoh's ``transport.link.tls`` (PEM). Any unset field stays unset."""

    root_ca_certificate: NonEmpty | None = None
    listen_certificate: NonEmpty | None = None
    listen_private_key: NonEmpty | None = None
    connect_certificate: NonEmpty | None = None
    connect_private_key: NonEmpty | None = None
    enable_mtls: bool = False

    def check(self, where: str, raw: Mapping[str, Any]) -> "TlsConfig":
        _pair(where, raw, "listen_certificate", "listen_private_key")
        _pair(where, raw, "connect_certificate", "connect_private_key")
        return self


class AuthConfig(msgspec.Struct, frozen=True):
    """zenoh user/password authentication (``transport.auth.usrpwd``)."""

    user: NonEmpty | None = None
    password: NonEmpty | None = None
    dictionary_file: NonEmpty | None = None

    def check(self, where: str, raw: Mapping[str, Any]) -> "AuthConfig":
        _pair(where, raw, "user", "password")
        return self


class ZenohConfig(msgspec.Struct, frozen=True):
    """How the daemon joins the Zenoh network (default: loopback-only embedded peer)."""

    mode: Literal["peer", "client"] = "peer"
    listen: Endpoints = ("tcp/127.0.0.1:7447",)  # default: none in client mode
    connect: Endpoints = ()
    multicast_scouting: bool = False
    status_interval_s: Annotated[float, Meta(gt=0, le=1)] = 1.0  # status at >= 1 Hz
    tls: TlsConfig | None = None
    auth: AuthConfig | None = None

    def check(self, where: str, raw: Mapping[str, Any]) -> "ZenohConfig":
        for key in ("listen", "connect"):
            check_endpoints(where, key, getattr(self, key))
        if self.mode == "client" and not self.connect:
            raise error(where, "connect", [], "client mode needs at least one endpoint")
        if self.mode == "client" and "listen" not in raw:
            return msgspec.structs.replace(self, listen=())
        return self


class StateConfig(msgspec.Struct, frozen=True):
    """Where and how often the crash-safe checkpoint is written."""

    path: NonEmpty = "buoymon-state.sqlite"
    checkpoint_interval_s: Positive = 10.0


class RecordConfig(msgspec.Struct, frozen=True):
    """MCAP recording of every received and published message by the daemon."""

    enabled: bool = False  # default: on when ``dir`` is given
    dir: NonEmpty = "record"
    rotate_s: Positive = 3600.0
    flush_interval_s: Positive = 5.0

    def check(self, where: str, raw: Mapping[str, Any]) -> "RecordConfig":
        if "enabled" not in raw and "dir" in raw:
            return msgspec.structs.replace(self, enabled=True)
        return self


class StreamAges(msgspec.Struct, frozen=True):
    """Data-age timeout (s) per sensor stream; ``ages["gnss"]`` reads one by name."""

    tension: Positive = 5.0
    motion: Positive = 5.0
    imu: Positive = 5.0
    gnss: Positive = 10.0
    waves: Positive = 3600.0

    def __getitem__(self, stream: str) -> float:
        return float(getattr(self, stream))


assert set(StreamAges.__struct_fields__) == set(SENSOR_FIELDS)  # one timeout per stream


class HealthConfig(msgspec.Struct, frozen=True):
    """Wall-clock liveness: data-age timeouts per sensor stream (seconds since the last block
    arrived) and the live (wall-clock) alert rules of :mod:`monitor.alerts.live`."""

    data_age_timeout_s: StreamAges = msgspec.field(default_factory=StreamAges)
    live_rules: bool = True              # off switch for every wall-clock alert rule
    # alert on these even if never seen (age from start)
    required_streams: Annotated[tuple[str, ...], Meta(
        description=f"a list of sensor streams from {sorted(SENSOR_FIELDS)}")] = ()
    fatigue_blind_timeout_s: Positive = 60.0   # no load sample fed fatigue for this long
    clock_skew_max_s: Positive = 600.0         # |sensor time - logger clock| allowed per block
    time_restart_min_s: Positive = 1.0         # a stream going back by more is a time restart
    hold_s: Positive = 600.0                   # counter-increase alerts stay on this long
    delivery_stall_s: Positive = 30.0          # an alert undelivered this long is alerted

    def check(self, where: str, raw: Mapping[str, Any]) -> "HealthConfig":
        if any(s not in SENSOR_FIELDS for s in self.required_streams):
            raise error(where, "required_streams", list(self.required_streams),
                        f"must be a list of sensor streams from {sorted(SENSOR_FIELDS)}")
        return self


class MetricsConfig(msgspec.Struct, frozen=True):
    """Prometheus exposition (``/metrics``) and ``/healthz`` over HTTP (loopback by default)."""

    enabled: bool = True
    listen: Annotated[str, Meta(min_length=1, description="a non-empty host address string")
                      ] = "127.0.0.1"
    port: Annotated[int, Meta(ge=0, le=65535, description="an integer port 0..65535 (0: any free)")
                    ] = 9464


class DaemonConfig(msgspec.Struct, frozen=True):
    """All daemon sections together."""

    zenoh: ZenohConfig = msgspec.field(default_factory=ZenohConfig)
    state: StateConfig = msgspec.field(default_factory=StateConfig)
    record: RecordConfig = msgspec.field(default_factory=RecordConfig)
    health: HealthConfig = msgspec.field(default_factory=HealthConfig)
    metrics: MetricsConfig = msgspec.field(default_factory=MetricsConfig)


def parse_daemon_sections(raw: Mapping[str, Any]) -> DaemonConfig:
    """Parse the daemon's sections out of a whole TOML document (absent ones get defaults);
    the errors of every section at once."""
    errors = Errors()
    sections: dict[str, Any] = {
        f.name: errors.parse(parse_struct, f.type, raw.get(f.name), f.name)
        for f in msgspec.structs.fields(DaemonConfig)}
    errors.raise_any()
    return DaemonConfig(**sections)
