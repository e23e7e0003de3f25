"""What the Rerun sink logs, how often, and where it goes (the ``[rerun]`` config section).

Logging every 20 Hz sample of every series would make a fast replay several times slower than
the fatigue computation itself (rerun ingests ~2-3 M scalars/s here), so high-rate series are
reduced to a min/max envelope per ``envelope_s`` of sensor time, slow figures (damage, rate,
life, health, position) are sampled every ``slow_interval_s`` and snapshots (rainflow histogram,
range-mean matrix, cable shape) every ``snapshot_interval_s``/``shape_interval_s``. The live
defaults give a 1 Hz dashboard; :meth:`RerunOptions.for_replay` is the coarser preset used by
``buoymon replay --rrd`` so month-long logs stay within the 2x time budget.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any, Mapping

from monitor.schema import ConfigError, check_keys
from monitor.viz.cycle_histogram import DEFAULT_MEAN_EDGES_Pa, DEFAULT_RANGE_EDGES_Pa, check_edges


@dataclass(frozen=True)
class RerunOptions:
    """Settings of :class:`monitor.viz.rerun_sink.RerunSink` and its outputs.

    Attributes:
        envelope_s: bin width (s of sensor time) of the min/max envelope of load and stress;
            0 logs every sample.
        slow_interval_s: spacing of damage, damage rate, remaining life, measured/estimated
            tension, sensor health and buoy position points.
        snapshot_interval_s: spacing of rainflow histogram and range-mean matrix snapshots.
        shape_interval_s: spacing of 3D cable-shape updates.
        flush_samples: flush buffered data to Rerun after this many buffered input samples.
        flush_interval_s: ... or after this many wall-clock seconds (bounds live latency and
            memory).
        range_edges_Pa: bin edges of the rainflow histogram (stress range); ranges above the
            last edge are counted in the last bin.
        mean_edges_Pa: bin edges of the mean axis of the range-mean matrix (clipped likewise).
        anchor_lat_deg / anchor_lon_deg: origin of the position view (NaN: first GNSS fix).
        watch_circle_m: radius of the watch circle drawn around the anchor (0: none).
        bearing_deg: compass bearing anchor -> buoy of the mooring, orients the 3D line.
        rrd: path of a recording file ("" for none).
        connect: gRPC URL of a running viewer, e.g. ``rerun+http://127.0.0.1:9876/proxy``.
        serve_web: start a web viewer on 127.0.0.1 (``rerun --serve-web --bind 127.0.0.1``).
        web_port / grpc_port: ports of the served web viewer and its gRPC proxy.
        server_memory_limit: memory cap of the served viewer's buffer (oldest data dropped).
    """

    envelope_s: float = 1.0
    slow_interval_s: float = 1.0
    snapshot_interval_s: float = 1.0
    shape_interval_s: float = 1.0
    flush_samples: int = 200_000
    flush_interval_s: float = 1.0
    range_edges_Pa: tuple[float, ...] = DEFAULT_RANGE_EDGES_Pa
    mean_edges_Pa: tuple[float, ...] = DEFAULT_MEAN_EDGES_Pa
    anchor_lat_deg: float = math.nan
    anchor_lon_deg: float = math.nan
    watch_circle_m: float = 0.0
    bearing_deg: float = 0.0
    rrd: str = ""
    connect: str = ""
    serve_web: bool = False
    web_port: int = 9090
    grpc_port: int = 9876
    server_memory_limit: str = "256MiB"

    def __post_init__(self) -> None:
        for name in ("envelope_s", "slow_interval_s", "snapshot_interval_s", "shape_interval_s",
                     "flush_interval_s", "watch_circle_m"):
            v = getattr(self, name)
            if (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                    or v < 0):
                raise ConfigError(
                    f"config error: rerun.{name} = {v!r}: must be a finite number >= 0")
        for name, limit in (("anchor_lat_deg", 90.0), ("anchor_lon_deg", 180.0),
                            ("bearing_deg", 360.0)):
            v = getattr(self, name)
            nan_ok = name != "bearing_deg"  # NaN anchor: use the first GNSS fix
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    abs(v) <= limit or (nan_ok and math.isnan(v))):
                raise ConfigError(f"config error: rerun.{name} = {v!r}: must be within "
                                 f"[-{limit:g}, {limit:g}]")
        if not isinstance(self.flush_samples, int) or self.flush_samples < 1:
            raise ConfigError(
                f"config error: rerun.flush_samples = {self.flush_samples!r}: "
                "must be an integer >= 1"
            )
        for name in ("range_edges_Pa", "mean_edges_Pa"):
            try:
                edges = check_edges(getattr(self, name), f"config error: rerun.{name}")
            except ValueError as exc:  # check_edges serves the report too: a ValueError
                raise ConfigError(str(exc)) from None
            object.__setattr__(self, name, tuple(edges.tolist()))  # frozen: normalise once
        for name in ("web_port", "grpc_port"):
            p = getattr(self, name)
            if not isinstance(p, int) or not 0 <= p <= 65535:
                raise ConfigError(f"config error: rerun.{name} = {p!r}: must be a port 0-65535")
        for name in ("rrd", "connect", "server_memory_limit"):
            if not isinstance(getattr(self, name), str):
                raise ConfigError(
                    f"config error: rerun.{name} = {getattr(self, name)!r}: must be a string")
        if not isinstance(self.serve_web, bool):
            raise ConfigError(
                f"config error: rerun.serve_web = {self.serve_web!r}: must be true/false")
        schemes = ("rerun://", "rerun+http://", "rerun+https://")
        if self.connect and not self.connect.startswith(schemes):
            raise ConfigError(
                f"config error: rerun.connect = {self.connect!r}: must be a rerun:// or "
                "rerun+http(s):// URL, e.g. rerun+http://127.0.0.1:9876/proxy"
            )

    @classmethod
    def from_toml(cls, section: Mapping[str, Any]) -> "RerunOptions":
        """Build from the ``[rerun]`` table of the config file; unknown keys are errors."""
        return cls(**check_keys("rerun", section, (f.name for f in fields(cls))))

    def for_replay(self) -> "RerunOptions":
        """Coarser sampling for bulk replay of long logs (same entities as live)."""
        return replace(
            self,
            slow_interval_s=max(self.slow_interval_s, 10.0),
            snapshot_interval_s=max(self.snapshot_interval_s, 3600.0),
            shape_interval_s=max(self.shape_interval_s, 60.0),
            flush_samples=max(self.flush_samples, 2_000_000),
            flush_interval_s=max(self.flush_interval_s, 30.0),
        )
