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
from typing import Annotated, Any, Mapping

import msgspec
from msgspec import Meta

from monitor.schema import error
from monitor.viz.cycle_histogram import DEFAULT_MEAN_EDGES_Pa, DEFAULT_RANGE_EDGES_Pa, check_edges

Spacing = Annotated[float, Meta(ge=0)]
Port = Annotated[int, Meta(ge=0, le=65535, description="a port 0-65535")]
_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")


class RerunOptions(msgspec.Struct, frozen=True):
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
        anchor_lat_deg / anchor_lon_deg: origin of the position view (unset: first GNSS fix).
        watch_circle_m: radius of the watch circle drawn around the anchor (0: none).
        bearing_deg: compass bearing anchor -> buoy of the mooring, orients the 3D line.
        rrd: path of a recording file ("" for none).
        connect: gRPC URL of a running viewer, e.g. ``rerun+http://127.0.0.1:9876/proxy``.
        serve_web: start a web viewer on 127.0.0.1 (``rerun --serve-web --bind 127.0.0.1``).
        web_port / grpc_port: ports of the served web viewer and its gRPC proxy.
        server_memory_limit: memory cap of the served viewer's buffer (oldest data dropped).
    """

    envelope_s: Spacing = 1.0
    slow_interval_s: Spacing = 1.0
    snapshot_interval_s: Spacing = 1.0
    shape_interval_s: Spacing = 1.0
    flush_samples: Annotated[int, Meta(ge=1)] = 200_000
    flush_interval_s: Spacing = 1.0
    range_edges_Pa: tuple[float, ...] = DEFAULT_RANGE_EDGES_Pa
    mean_edges_Pa: tuple[float, ...] = DEFAULT_MEAN_EDGES_Pa
    anchor_lat_deg: Annotated[float, Meta(ge=-90, le=90)] = math.nan
    anchor_lon_deg: Annotated[float, Meta(ge=-180, le=180)] = math.nan
    watch_circle_m: Spacing = 0.0
    bearing_deg: Annotated[float, Meta(ge=-360, le=360)] = 0.0
    rrd: str = ""
    connect: str = ""
    serve_web: bool = False
    web_port: Port = 9090
    grpc_port: Port = 9876
    server_memory_limit: str = "256MiB"

    def check(self, where: str, raw: Mapping[str, Any]) -> "RerunOptions":
        """Edges at least two, finite and increasing; a viewer URL of rerun's schemes."""
        edges = {}
        for name in ("range_edges_Pa", "mean_edges_Pa"):
            try:
                edges[name] = tuple(check_edges(getattr(self, name), "").tolist())
            except ValueError:  # check_edges serves the report too, its message names no key
                raise error(where, name, raw.get(name), "must be at least two finite, "
                            "strictly increasing values") from None
        if self.connect and not self.connect.startswith(_SCHEMES):
            raise error(where, "connect", self.connect, "must be a rerun:// or rerun+http(s):// "
                        "URL, e.g. rerun+http://127.0.0.1:9876/proxy")
        return msgspec.structs.replace(self, **edges)

    def for_replay(self) -> "RerunOptions":
        """Coarser sampling for bulk replay of long logs (same entities as live)."""
        return msgspec.structs.replace(
            self,
            slow_interval_s=max(self.slow_interval_s, 10.0),
            snapshot_interval_s=max(self.snapshot_interval_s, 3600.0),
            shape_interval_s=max(self.shape_interval_s, 60.0),
            flush_samples=max(self.flush_samples, 2_000_000),
            flush_interval_s=max(self.flush_interval_s, 30.0),
        )
