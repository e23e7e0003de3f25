"""The ``[forecast]`` section: the damage-rate table learned on the buoy, forecast alerts and
the per-window spectral cross-check (docs/FORECAST.md)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from monitor.schema import SectionReader

SEVERITIES = ("info", "warning", "critical")


@dataclass(frozen=True)
class ForecastConfig:
    """``[forecast]``.

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
    window_s: float = 1800.0
    min_coverage: float = 0.5
    waves_max_age_s: float = 3600.0
    min_hours: float = 1.0
    table: str | None = None
    alert_damage: float = 0.5
    alert_severity: str = "warning"
    spectral_flag_factor: float = 3.0

    @classmethod
    def from_dict(cls, d: Any, where: str = "forecast") -> "ForecastConfig":
        r = SectionReader(d, where)
        table = r.raw("table", None)
        if table is not None and (not isinstance(table, str) or not table):
            raise r.error("table", table, "must be the path of a saved table (JSON)")
        out = cls(
            enabled=r.bool("enabled", cls.enabled),
            window_s=r.float("window_s", cls.window_s, gt=0),
            min_coverage=r.float("min_coverage", cls.min_coverage, gt=0, le=1),
            waves_max_age_s=r.float("waves_max_age_s", cls.waves_max_age_s, ge=0),
            min_hours=r.float("min_hours", cls.min_hours, gt=0),
            table=table,
            alert_damage=r.float("alert_damage", cls.alert_damage, gt=0),
            alert_severity=r.str("alert_severity", cls.alert_severity, SEVERITIES),
            spectral_flag_factor=r.float("spectral_flag_factor", cls.spectral_flag_factor, gt=1),
        )
        r.done()
        return out
