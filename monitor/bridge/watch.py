"""The daemon's view of the bridges feeding it: their status documents on
``buoy/<id>/bridge/status`` (a ``buoymon bridge`` process, or the bridge inside the daemon)
merged per source into the daemon's status under ``bridge``, so ``buoymon status``, the
Prometheus metrics (``buoymon_bridge_*``) and the live rule ``bridge_source`` see them.

A bridge that dies publishes nothing more: a source whose last report is older than
``max(3 x the bridge's status interval, MIN_SILENT_S)`` is shown in state ``silent`` (one
that stopped cleanly said ``stopped`` in its last status, and stays so). The ages a bridge
reports (``last_line_age_s``, ``last_sample_age_s``) were true when it reported: the daemon
adds the report's age, so they keep growing while a bridge is silent instead of freezing.
"""

from __future__ import annotations

import json
import threading
import time
from typing import Any

# a bridge's status older than this (and than three of its intervals) means the bridge is gone
MIN_SILENT_S = 3.0
# a source's ages in a bridge's report, in seconds as of the report
_AGES = ("last_line_age_s", "last_sample_age_s")


class BridgeWatch:
    """Daemon extension (:class:`monitor.daemon.Extension`) following the bridge status key."""

    def __init__(self, session: Any, buoy_id: str) -> None:
        self._lock = threading.Lock()
        # source name -> (its entry of the last status naming it, arrival, silent after s)
        self._sources: dict[str, tuple[dict[str, Any], float, float]] = {}
        self._sub = session.declare_subscriber(f"buoy/{buoy_id}/bridge/status", self._on_status)

    def _on_status(self, sample: Any) -> None:  # zenoh's thread: parse and store only
        try:
            doc = json.loads(sample.payload.to_bytes())
            silent_s = max(3 * float(doc.get("status_interval_s", 1.0)), MIN_SILENT_S)
            sources = {str(k): dict(v) for k, v in doc["sources"].items()}
        except (ValueError, TypeError, KeyError, AttributeError):
            return  # not a bridge status: nothing to show
        now = time.monotonic()
        with self._lock:
            for name, entry in sources.items():
                self._sources[name] = (entry, now, silent_s)

    def poll(self) -> None:
        """Nothing to do between blocks (the subscriber stores as documents arrive)."""

    def status_fields(self) -> dict[str, Any]:
        """``{"bridge": {"sources": {name: entry + status_age_s}}}``, or nothing while no
        bridge has reported."""
        now = time.monotonic()
        with self._lock:
            items = list(self._sources.items())
        if not items:
            return {}
        out = {}
        for name, (entry, arrived, silent_s) in sorted(items):
            age = now - arrived
            shown = {**entry, "status_age_s": age}
            for key in _AGES:  # as of now, not as of the report (module docstring)
                if isinstance(entry.get(key), (int, float)):
                    shown[key] = entry[key] + age
            if age > silent_s and entry.get("state") != "stopped":
                shown["state"] = "silent"
            out[name] = shown
        return {"bridge": {"sources": out}}

    def close(self) -> None:
        self._sub.undeclare()
