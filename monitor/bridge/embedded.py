"""The bridge inside the daemon (``[[source]]`` in the daemon's configuration): one process
logs the instruments and monitors them.

The bridge publishes through the daemon's own Zenoh session, so its blocks reach the daemon's
subscriber as a separate bridge's would (same encoding, cache and liveliness) and any other
subscriber (a shore monitor, ``buoymon record``) sees them too. It runs in a thread of its
own, started at the first :meth:`poll`, after the daemon has subscribed: the instruments are
read at their pace whatever the daemon is doing (a checkpoint, a backlog), and their bytes
never wait in a kernel buffer that could overflow. When the daemon stops, the bridge stops
first (:meth:`finish_input`): its last blocks reach the daemon before it stops intake.
"""

from __future__ import annotations

import threading
from typing import Any

from monitor.bridge.config import BridgeConfig
from monitor.bridge.runner import Bridge
from monitor.sensors import PublisherOptions, SensorPublisher


class EmbeddedBridge:
    """Daemon extension (:class:`monitor.daemon.Extension`) running ``cfg``'s sources."""

    def __init__(self, session: Any, cfg: BridgeConfig) -> None:
        self.bridge = Bridge(cfg, SensorPublisher(
            session, cfg.buoy_id, PublisherOptions(cache_blocks=cfg.cache_blocks)))
        self._thread: threading.Thread | None = None

    def poll(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self.bridge.run, name="bridge", daemon=True)
            self._thread.start()

    def finish_input(self) -> None:
        """Stop reading and publish what is buffered (the daemon still listens)."""
        if self._thread is not None:
            self.bridge.stop()
            self._thread.join(10.0)

    def close(self) -> None:
        self.finish_input()
        self.bridge.publisher.close()  # its publishers only: the session is the daemon's
