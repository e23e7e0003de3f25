"""Where a command finds the daemon of a configuration: buoy id, endpoints, state file.

Read straight from the TOML (``[buoy] id``, ``[zenoh]``, ``[state] path``) without building
the pipeline, so ``buoymon status`` and ``buoymon alerts`` start fast. A separate bridge's own
file (``[[source]]`` tables, no ``[[component]]``: docs/SENSORS.md) names the daemon it
publishes to in ``[bridge] connect``: that is where the daemon is asked; it names no state file.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from monitor.blocks import validate_buoy_id
from monitor.bridge.config import BridgeSection
from monitor.daemon_config import parse_daemon_sections
from monitor.schema import parse_struct, read_toml

DEFAULT_CONFIG = "/etc/buoymon/buoymon.toml"  # the path of packaging/systemd/buoymon.service
DEFAULT_CONNECT = "tcp/127.0.0.1:7447"


def endpoint_arg(value: str) -> str:
    """The argparse type of an ``ENDPOINT`` option: checked as a ``[zenoh] connect`` entry
    is, so a malformed one is a usage error, not a Zenoh traceback or "not running"."""
    try:
        parse_daemon_sections({"zenoh": {"connect": [value]}})
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{value!r} is not a Zenoh endpoint: expected <proto>/<address>, e.g. "
            f"{DEFAULT_CONNECT}") from None
    return value


@dataclass(frozen=True)
class DaemonTarget:
    buoy_id: str
    connect: tuple[str, ...]  # endpoints a client reaches the daemon on
    state_path: str | None  # None: a bridge's file names no daemon state file
    origin: str = "[zenoh] listen/connect"  # where ``connect`` came from, for the messages


def _reachable(endpoint: str) -> str:
    """A listen endpoint as a client connects to it: any-address binds become loopback."""
    proto, _, addr = endpoint.partition("/")
    for anywhere in ("0.0.0.0:", "[::]:"):
        if addr.startswith(anywhere):
            addr = "127.0.0.1:" + addr[len(anywhere):]
    return f"{proto}/{addr}"


def load_target(path: str) -> DaemonTarget:
    """The daemon of configuration file ``path`` (ValueError naming key and value)."""
    if not Path(path).exists():
        hint = " (the systemd unit's default; pass --config CFG.toml)" \
            if path == DEFAULT_CONFIG else ""
        raise ValueError(f"config error: {path}: no such file{hint}")
    raw = read_toml(path)
    buoy = raw.get("buoy", {}).get("id") if isinstance(raw.get("buoy"), dict) else None
    if not isinstance(buoy, str):
        raise ValueError(f"config error: {path}: buoy.id = {buoy!r}: must be a string")
    if "source" in raw and "component" not in raw:  # a bridge's file, as check-config tells
        bridge = parse_struct(BridgeSection, raw.get("bridge"), "bridge")
        return DaemonTarget(validate_buoy_id(buoy), bridge.connect, None,
                            f"[bridge] connect of the bridge configuration {path}")
    daemon = parse_daemon_sections(raw)
    connect = tuple(_reachable(e) for e in daemon.zenoh.listen) + daemon.zenoh.connect
    return DaemonTarget(validate_buoy_id(buoy), connect or (DEFAULT_CONNECT,), daemon.state.path)
