"""The visual sinks of a configured pipeline: what replay (``--rrd``, ``--html``), the demo and
the daemon (``[rerun]`` section) attach to the pipeline core.

The Rerun sink gets the mooring line's shape from the configured mooring and the position view's
anchor, bearing and watch circle from ``[mooring]`` unless ``[rerun]`` sets them. The report's
optional plot fields come from a :class:`~monitor.viz.report_history.ReportHistory` sink plus each
component's S-N curve (:func:`report_plot_fields`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

import msgspec
import numpy as np

from monitor.config import Config
from monitor.viz.rerun_options import RerunOptions
from monitor.viz.rerun_outputs import WebViewer, open_rerun_sink
from monitor.viz.rerun_sink import RerunSink, ShapeProvider
from monitor.viz.report_history import ReportHistory, sn_curve_field


def mooring_line(config: Config) -> Any:
    """The configured mooring as a ``models.catenary.Line`` (anchor -> buoy)."""
    from models import catenary

    m = config.mooring
    if m.preset == "vaps_seed004":
        return catenary.vaps_mooring()
    return catenary.Line(segments=tuple(
        catenary.Segment(s.length_m, s.weight_N_per_m, s.ea_N, s.name) for s in m.segments))


def shape_provider(config: Config) -> ShapeProvider:
    """Top tension -> the configured line's profile, for the 3D view. A tension below the
    line's slack minimum (the buoy over the anchor; a snapping line goes slack between waves)
    is drawn as the slack line, not skipped."""
    from models.catenary import solve
    from monitor.viz.cable_shape import catenary_shape_provider

    line, depth = mooring_line(config), config.mooring.depth_m
    slack = float(np.asarray(solve(line, np.array([0.0]), np.array([depth])).t_top).ravel()[0])
    profile = catenary_shape_provider(line, depth)

    def shape(top_tension_N: float) -> tuple[np.ndarray, np.ndarray]:
        return profile(max(float(top_tension_N), slack))

    return shape


def rerun_options(config: Config) -> RerunOptions:
    """``[rerun]`` of the configuration, the mooring's anchor and bearing filled in, and a
    watch circle of the line's horizontal reach (sqrt(length^2 - depth^2)) unless set."""
    section, opts, m = config.section("rerun"), config.rerun, config.mooring
    fill: dict[str, Any] = {}
    if "anchor_lat_deg" not in section and math.isfinite(m.anchor_lat_deg):
        fill["anchor_lat_deg"] = m.anchor_lat_deg
    if "anchor_lon_deg" not in section and math.isfinite(m.anchor_lon_deg):
        fill["anchor_lon_deg"] = m.anchor_lon_deg
    if "bearing_deg" not in section:
        fill["bearing_deg"] = m.bearing_deg
    if "watch_circle_m" not in section and m.length_m > m.depth_m:
        fill["watch_circle_m"] = math.sqrt(m.length_m ** 2 - m.depth_m ** 2)
    return msgspec.structs.replace(opts, **fill)


class ViewerSink:
    """A Rerun sink that also stops the web viewer it was served with when it is closed."""

    def __init__(self, sink: RerunSink, viewer: WebViewer | None) -> None:
        self.sink, self.viewer = sink, viewer

    def __getattr__(self, name: str) -> Any:  # on_step, on_block, on_alert, flush, ...
        return getattr(self.sink, name)

    def close(self) -> None:
        try:
            self.sink.close()
        finally:
            if self.viewer is not None:
                self.viewer.stop()


def open_rerun(config: Config, *, rrd: str | Path | None = None, replay: bool = False
               ) -> ViewerSink:
    """The Rerun sink of a configured pipeline: ``rrd`` (replay's ``--rrd``) or the ``[rerun]``
    outputs; ``replay=True`` uses the bulk sampling preset. ValueError if there is no output."""
    sink, viewer = open_rerun_sink(config.buoy.id, rerun_options(config), rrd=rrd,
                                   shape_provider=shape_provider(config), replay=replay)
    return ViewerSink(sink, viewer)


SN_MAX_CYCLES = 1e12  # S-N points beyond this life are left out of the plot (no log is
#                      that long, and Haibach tails reach 1e300, which a log axis cannot draw)


def report_plot_fields(history: ReportHistory, components: Mapping[str, Any]
                       ) -> dict[str, Any]:
    """The report's optional plot fields (docs/REPORT_FORMAT.md): the history sink's series and,
    per component, its S-N curve over the stresses seen (points with lives up to
    ``SN_MAX_CYCLES``). ``components`` maps names to objects with ``sn_curve`` and
    ``max_stress_Pa`` (the pipeline's components)."""
    out = history.fields()
    comps = out.setdefault("components", {})
    for name, comp in components.items():
        peak = comp.max_stress_Pa if math.isfinite(comp.max_stress_Pa) else 0.0
        top = max(peak, (getattr(comp.sn_curve, "endurance_MPa", None) or 0.0) * 1e6, 1e6)
        field = sn_curve_field(comp.sn_curve, top)
        keep = [i for i, n in enumerate(field["cycles"])
                if not isinstance(n, str) and n <= SN_MAX_CYCLES]
        field["ranges_Pa"] = [field["ranges_Pa"][i] for i in keep]
        field["cycles"] = [field["cycles"][i] for i in keep]
        comps.setdefault(name, {})["sn_curve"] = field
    return out
