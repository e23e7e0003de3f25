"""The ``[forecast]`` section: the damage-rate table learned on the buoy, forecast alerts and
the per-window spectral cross-check (docs/FORECAST.md)."""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec
from msgspec import Meta

Positive = Annotated[float, Meta(gt=0)]


class ForecastConfig(msgspec.Struct, frozen=True):
    """``[forecast]`` (parsed by :func:`monitor.schema.parse_struct`).

    Attributes:
        enabled: learn the table, accept forecasts, run the cross-check.
        window_s: length of a learning window (a whole number of alert ticks): its damage
            and sea state make one entry of the table.
        min_coverage: fraction of a window that must have had load samples to be learned.
        waves_max_age_s: a window without a ``waves`` sample of its own takes the newest
            earlier one if at most this old at the window's end.
        min_hours: data hours from which a bin's learned rate replaces the model's.
        table: a saved table (``buoymon forecast --save-table``) whose bins (model rates and
            any learned data) the buoy starts from; None: empty default bins.
        alert_damage: ``forecast_damage`` fires when a forecast's projected damage reaches it.
        alert_severity: that alert's severity.
        spectral_flag_factor: a window whose Dirlik and rainflow damage differ by more than
            this factor (either way) is flagged.
    """

    enabled: bool = True
    window_s: Positive = 1800.0
    min_coverage: Annotated[float, Meta(gt=0, le=1)] = 0.5
    waves_max_age_s: Annotated[float, Meta(ge=0)] = 3600.0
    min_hours: Positive = 1.0
    table: Annotated[str, Meta(min_length=1,
                               description="the path of a saved table (JSON)")] | None = None
    alert_damage: Positive = 0.5
    alert_severity: Literal["info", "warning", "critical"] = "warning"
    spectral_flag_factor: Annotated[float, Meta(gt=1)] = 3.0
