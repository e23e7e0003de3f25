"""The bridge inside the daemon (``[[source]]`` in the daemon's configuration): one process
logs the instruments and monitors them.

The bridge publishes through the daemon's own Zenoh session, so its blocks reach the daemon's
subscriber as a separate bridge's would (same encoding, cache and liveliness) and any other
subscriber (a shore monitor, ``buoymon record``) sees them too. Its readers start at the
first :meth:`poll`, after the daemon has subscribed, and its work runs on the daemon's
thread between blocks, for at most ``_BUDGET_S`` per turn. When the daemon stops, the bridge
stops first (:meth:`finish_input`): its last blocks reach the daemon before it stops intake.
"""

from __future__ import annotations

from typing import Any

from monitor.bridge.config import BridgeConfig
from monitor.bridge.runner import Bridge
from monitor.sensors import PublisherOptions, SensorPublisher

_BUDGET_S = 0.1  # longest stretch of bridge work per daemon turn


class EmbeddedBridge:
    """Daemon extension (:class:`monitor.daemon.Extension`) running ``cfg``'s sources."""

    def __init__(self, session: Any, cfg: BridgeConfig) -> None:
        self.bridge = Bridge(cfg, SensorPublisher(
            session, cfg.buoy_id, PublisherOptions(cache_blocks=cfg.cache_blocks)))
        self._opened = False

    def poll(self) -> None:
        if not self._opened:
            self.bridge.open()
            self._opened = True
        self.bridge.step(0.0, _BUDGET_S)

    def finish_input(self) -> None:
        """Stop reading and publish what is buffered (the daemon still listens)."""
        if self._opened:
            self.bridge.close()
            self._opened = False

    def close(self) -> None:
        self.finish_input()
        self.bridge.publisher.close()  # its publishers only: the session is the daemon's
