"""Configuration sections of the live daemon: ``[zenoh]``, ``[state]``, ``[record]``, ``[health]``.

Each section is a frozen dataclass with ``from_dict(d, where)``; ``where`` is the section's
dotted name used in error messages, which always name the bad key and value, e.g.
``config error: zenoh.mode = 'router': must be one of ['client', 'peer']``.
:func:`parse_daemon_sections` reads all four from a whole-file TOML mapping (missing
sections take their defaults), so ``monitor.config`` can include them as they are.

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

import math
import re
from dataclasses import dataclass, field
from typing import Any, Mapping

from monitor.blocks import SENSOR_FIELDS

_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws|unixsock-stream)/\S+$")


def _err(where: str, key: str, value: Any, why: str) -> ValueError:
    return ValueError(f"config error: {where}.{key} = {value!r}: {why}")


def _check_keys(d: Any, where: str, allowed: set[str]) -> Mapping[str, Any]:
    if not isinstance(d, Mapping):
        raise ValueError(f"config error: [{where}] must be a table, got {d!r}")
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise _err(where, unknown[0], d[unknown[0]], f"unknown key; allowed: {sorted(allowed)}")
    return d


def _positive(d: Mapping[str, Any], where: str, key: str, default: float) -> float:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise _err(where, key, v, "must be a finite number > 0")
    return float(v)


def _bool(d: Mapping[str, Any], where: str, key: str, default: bool) -> bool:
    v = d.get(key, default)
    if not isinstance(v, bool):
        raise _err(where, key, v, "must be true or false")
    return v


def _opt_str(d: Mapping[str, Any], where: str, key: str) -> str | None:
    v = d.get(key)
    if v is not None and (not isinstance(v, str) or not v):
        raise _err(where, key, v, "must be a non-empty string")
    return v


def _endpoints(d: Mapping[str, Any], where: str, key: str, default: list[str]) -> tuple[str, ...]:
    v = d.get(key, default)
    if not isinstance(v, list):
        raise _err(where, key, v, "must be a list of endpoint strings like 'tcp/127.0.0.1:7447'")
    for e in v:
        if not isinstance(e, str) or not _ENDPOINT.match(e):
            raise _err(where, key, v, f"endpoint {e!r} is not of the form '<proto>/<address>'")
    return tuple(v)


@dataclass(frozen=True)
class TlsConfig:
    """File paths for zenoh's ``transport.link.tls`` (PEM). Any unset field stays unset."""

    root_ca_certificate: str | None = None
    listen_certificate: str | None = None
    listen_private_key: str | None = None
    connect_certificate: str | None = None
    connect_private_key: str | None = None
    enable_mtls: bool = False

    @classmethod
    def from_dict(cls, d: Any, where: str) -> "TlsConfig":
        names = {f for f in cls.__dataclass_fields__}
        d = _check_keys(d, where, names)
        paths = {k: _opt_str(d, where, k) for k in names - {"enable_mtls"}}
        mtls = _bool(d, where, "enable_mtls", False)
        for a, b in (("listen_certificate", "listen_private_key"),
                     ("connect_certificate", "connect_private_key")):
            if (paths[a] is None) != (paths[b] is None):
                raise _err(where, a if paths[a] is None else b, None,
                           f"{a} and {b} must be given together")
        return cls(enable_mtls=mtls, **paths)


@dataclass(frozen=True)
class AuthConfig:
    """zenoh user/password authentication (``transport.auth.usrpwd``)."""

    user: str | None = None
    password: str | None = None
    dictionary_file: str | None = None

    @classmethod
    def from_dict(cls, d: Any, where: str) -> "AuthConfig":
        d = _check_keys(d, where, {"user", "password", "dictionary_file"})
        user, pw = _opt_str(d, where, "user"), _opt_str(d, where, "password")
        if (user is None) != (pw is None):
            raise _err(where, "user" if user is None else "password", None,
                       "user and password must be given together")
        return cls(user, pw, _opt_str(d, where, "dictionary_file"))


@dataclass(frozen=True)
class ZenohConfig:
    """How the daemon joins the Zenoh network (default: loopback-only embedded peer)."""

    mode: str = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    status_interval_s: float = 1.0
    tls: TlsConfig | None = None
    auth: AuthConfig | None = None

    @classmethod
    def from_dict(cls, d: Any, where: str = "zenoh") -> "ZenohConfig":
        d = _check_keys(d, where, {"mode", "listen", "connect", "multicast_scouting",
                                   "status_interval_s", "tls", "auth"})
        mode = d.get("mode", "peer")
        if mode not in ("peer", "client"):
            raise _err(where, "mode", mode, "must be one of ['client', 'peer']")
        default_listen = [] if mode == "client" else list(cls.listen)
        listen = _endpoints(d, where, "listen", default_listen)
        connect = _endpoints(d, where, "connect", [])
        if mode == "client" and not connect:
            raise _err(where, "connect", list(connect), "client mode needs at least one endpoint")
        interval = _positive(d, where, "status_interval_s", 1.0)
        if interval > 1.0:
            raise _err(where, "status_interval_s", interval, "must be <= 1 (status at >= 1 Hz)")
        tls = TlsConfig.from_dict(d["tls"], f"{where}.tls") if "tls" in d else None
        auth = AuthConfig.from_dict(d["auth"], f"{where}.auth") if "auth" in d else None
        return cls(mode, listen, connect, _bool(d, where, "multicast_scouting", False),
                   interval, tls, auth)


@dataclass(frozen=True)
class StateConfig:
    """Where and how often the crash-safe checkpoint is written."""

    path: str = "buoymon-state.sqlite"
    checkpoint_interval_s: float = 10.0

    @classmethod
    def from_dict(cls, d: Any, where: str = "state") -> "StateConfig":
        d = _check_keys(d, where, {"path", "checkpoint_interval_s"})
        path = d.get("path", cls.path)
        if not isinstance(path, str) or not path:
            raise _err(where, "path", path, "must be a non-empty string")
        return cls(path, _positive(d, where, "checkpoint_interval_s", cls.checkpoint_interval_s))


@dataclass(frozen=True)
class RecordConfig:
    """MCAP recording of every received and published message by the daemon."""

    enabled: bool = False
    dir: str = "record"
    rotate_s: float = 3600.0
    flush_interval_s: float = 5.0

    @classmethod
    def from_dict(cls, d: Any, where: str = "record") -> "RecordConfig":
        d = _check_keys(d, where, {"enabled", "dir", "rotate_s", "flush_interval_s"})
        directory = d.get("dir", cls.dir)
        if not isinstance(directory, str) or not directory:
            raise _err(where, "dir", directory, "must be a non-empty string")
        return cls(_bool(d, where, "enabled", "dir" in d), directory,
                   _positive(d, where, "rotate_s", cls.rotate_s),
                   _positive(d, where, "flush_interval_s", cls.flush_interval_s))


_DEFAULT_AGE = {"tension": 5.0, "motion": 5.0, "imu": 5.0, "gnss": 10.0, "waves": 3600.0}


@dataclass(frozen=True)
class HealthConfig:
    """Wall-clock liveness: data-age timeouts per sensor stream (seconds since the last block
    arrived) and the live (wall-clock) alert rules of :mod:`monitor.alerts.live`."""

    data_age_timeout_s: Mapping[str, float] = field(default_factory=lambda: dict(_DEFAULT_AGE))
    live_rules: bool = True              # off switch for every wall-clock alert rule
    required_streams: tuple[str, ...] = ()  # alert on these even if never seen (age from start)
    fatigue_blind_timeout_s: float = 60.0   # no load sample fed fatigue for this long
    clock_skew_max_s: float = 600.0         # |sensor time - logger clock| allowed per block
    time_restart_min_s: float = 1.0         # a stream going back by more is a time restart
    hold_s: float = 600.0                   # counter-increase alerts stay on this long

    @classmethod
    def from_dict(cls, d: Any, where: str = "health") -> "HealthConfig":
        d = _check_keys(d, where, {"data_age_timeout_s", "live_rules", "required_streams",
                                   "fatigue_blind_timeout_s", "clock_skew_max_s",
                                   "time_restart_min_s", "hold_s"})
        given = d.get("data_age_timeout_s", {})
        sub = f"{where}.data_age_timeout_s"
        given = _check_keys(given, sub, set(SENSOR_FIELDS))
        ages = dict(_DEFAULT_AGE)
        ages.update({k: _positive(given, sub, k, 1.0) for k in given})
        required = d.get("required_streams", [])
        if not isinstance(required, list) or any(s not in SENSOR_FIELDS for s in required):
            raise _err(where, "required_streams", required,
                       f"must be a list of sensor streams from {sorted(SENSOR_FIELDS)}")
        return cls(ages, _bool(d, where, "live_rules", True), tuple(required),
                   *(_positive(d, where, k, getattr(cls, k)) for k in (
                       "fatigue_blind_timeout_s", "clock_skew_max_s", "time_restart_min_s",
                       "hold_s")))


@dataclass(frozen=True)
class MetricsConfig:
    """Prometheus exposition (``/metrics``) and ``/healthz`` over HTTP (loopback by default)."""

    enabled: bool = True
    listen: str = "127.0.0.1"
    port: int = 9464

    @classmethod
    def from_dict(cls, d: Any, where: str = "metrics") -> "MetricsConfig":
        d = _check_keys(d, where, {"enabled", "listen", "port"})
        listen = d.get("listen", cls.listen)
        if not isinstance(listen, str) or not listen:
            raise _err(where, "listen", listen, "must be a non-empty host address string")
        port = d.get("port", cls.port)
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port < 65536:
            raise _err(where, "port", port, "must be an integer port 0..65535 (0: any free)")
        return cls(_bool(d, where, "enabled", True), listen, port)


@dataclass(frozen=True)
class DaemonConfig:
    """All daemon sections together."""

    zenoh: ZenohConfig = field(default_factory=ZenohConfig)
    state: StateConfig = field(default_factory=StateConfig)
    record: RecordConfig = field(default_factory=RecordConfig)
    health: HealthConfig = field(default_factory=HealthConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)


SECTIONS = {"zenoh": ZenohConfig, "state": StateConfig, "record": RecordConfig,
            "health": HealthConfig, "metrics": MetricsConfig}


def parse_daemon_sections(raw: Mapping[str, Any]) -> DaemonConfig:
    """Parse the daemon's sections out of a whole TOML document (absent ones get defaults)."""
    return DaemonConfig(**{name: cls.from_dict(raw.get(name, {}), name)
                           for name, cls in SECTIONS.items()})
