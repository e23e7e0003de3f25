"""The default Rerun dashboard: loads and damage on top, histograms and geometry in the middle,
alerts and sensor health at the bottom. Entity paths are those of :mod:`monitor.viz.rerun_sink`.
"""

from __future__ import annotations

from typing import Sequence

import rerun.blueprint as rrb

# series with many components: a legend in the plot would cover the lines, and the view's
# own hover and selection name each line
_LEGEND = rrb.PlotLegend(visible=False)


def default_blueprint(components: Sequence[str]) -> rrb.Blueprint:
    """The dashboard for a buoy whose fatigue components are ``components``."""
    loads = rrb.Horizontal(
        rrb.TimeSeriesView(origin="/tension", name="Tension (kN)", plot_legend=_LEGEND),
        rrb.TimeSeriesView(origin="/stress", name="Conductor stress (MPa)",
                           plot_legend=_LEGEND),
    )
    fatigue = rrb.Horizontal(
        # damage only grows: its upper left corner stays free for the legend
        rrb.TimeSeriesView(origin="/damage", name="Miner damage (committed / provisional)",
                           plot_legend=rrb.PlotLegend(corner="LeftTop")),
        rrb.TimeSeriesView(origin="/damage_rate", name="Damage rate (1/day)",
                           plot_legend=_LEGEND),
        rrb.TimeSeriesView(origin="/remaining_life", name="Remaining life (days)",
                           plot_legend=_LEGEND),
    )
    histograms = [rrb.BarChartView(origin=f"/rainflow/{c}/histogram",
                                   name=f"Rainflow ranges: {c}") for c in components]
    matrices = [rrb.TensorView(origin=f"/rainflow/{c}/range_mean",
                               name=f"Range x mean: {c}") for c in components]
    cycles = rrb.Tabs(*histograms, *matrices, name="Rainflow") if components else None
    geometry = rrb.Horizontal(
        *([cycles] if cycles is not None else []),
        rrb.Spatial3DView(origin="/mooring", name="Mooring line (m)"),
        rrb.Spatial2DView(origin="/position", name="Position and watch circle (m E/N)"),
    )
    spectral = rrb.Horizontal(
        rrb.TimeSeriesView(origin="/spectral", name="Damage per window: rainflow / Dirlik"),
        rrb.TimeSeriesView(origin="/forecast",
                           name="Forecast: damage at the forecast's end (band)"),
        rrb.Vertical(
            rrb.StateTimelineView(origin="/spectral_flags", name="Dirlik vs rainflow"),
            rrb.TimeSeriesView(origin="/sea_state", name="Sea state (Hs m, Tp s)"),
        ),
    )
    status = rrb.Horizontal(
        rrb.StateTimelineView(origin="/alerts/state", name="Alert states"),
        rrb.TextLogView(origin="/alerts/log", name="Alert log"),
        rrb.Vertical(
            rrb.StateTimelineView(origin="/tension/source", name="Load source"),
            rrb.TimeSeriesView(origin="/health", name="Sensor samples (accepted / rejected)"),
        ),
    )
    return rrb.Blueprint(
        rrb.Vertical(loads, fatigue, geometry, spectral, status, row_shares=[3, 3, 3, 2, 2]),
        # following: the time cursor on the newest data, so histograms, the range-mean
        # matrix and the position open complete (live: they keep up)
        rrb.TimePanel(timeline="sensor_time", play_state="following"),
        collapse_panels=True,
    )
