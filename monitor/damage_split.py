"""Committed damage split by the load source that produced it, with a band on the estimated part.

Attribution (per alert tick, so it is the same for any split of the data into blocks): the
damage a component commits in a tick is shared between ``measured`` and ``estimated`` in
proportion to the tick's load samples from each source. A cycle closes in the tick of its
last turning point, so a cycle spanning a source change is attributed to the tick where it
closes (an approximation, exact when the source does not change). Damage committed after the
last evaluated tick is ``unattributed`` until that tick ends (or if no alert rule runs).

Band on the estimated part: damage scales as stress^m (Basquin) and stress is proportional to
tension, so a relative tension error ``u`` of the motion estimator gives the damage factor
range ``[(1 - u)^m, (1 + u)^m]``, with ``m`` the slope of the S-N curve's first (highest
stress) segment, where the storm cycles that dominate the damage lie; on a multi-slope curve
(vaps_copper: 4.5 .. 63) the band of damage from low-stress cycles is wider than this.
``u`` is calibrated on the residual where both sources are there: the RMS of
``(estimated - measured) / measured`` over the ticks whose mean measured tension is at least
:data:`MIN_CAL_N` (the model-residual computation of the pipeline gives the tick means) once
:data:`MIN_CAL_TICKS` ticks have both; before that it is :data:`ASSUMED_ERROR`, an assumption:
seed 004 gives no validation of the motion estimator, and a quasi-static catenary plus linear
drag model is taken to be good to +-30 % in tension.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

ASSUMED_ERROR = 0.30
MIN_CAL_TICKS = 30
MIN_CAL_N = 100.0


class DamageSplit:
    """Per component: committed damage from measured and from estimated load."""

    def __init__(self, slopes: Mapping[str, float], state: Mapping[str, Any] | None = None):
        self.slopes = dict(slopes)
        st = state or {}
        self.parts = {n: dict(st.get("parts", {}).get(n, {"measured": 0.0, "estimated": 0.0,
                                                         "committed": 0.0}))
                      for n in slopes}
        self.cal_n = int(st.get("cal_n", 0))
        self.cal_sum_sq = float(st.get("cal_sum_sq", 0.0))

    def tick(self, committed: Mapping[str, float], n_measured: int, n_total: int,
             measured_mean: float, estimated_mean: float) -> None:
        """One evaluated tick: each component's committed damage at its end, its sample
        counts by source, and the tick means of the measured tension and the estimate."""
        for name, value in committed.items():
            p = self.parts[name]
            delta = value - p["committed"]
            p["committed"] = value
            if delta > 0:
                frac = n_measured / n_total if n_total else 0.0
                p["measured"] += delta * frac
                p["estimated"] += delta * (1.0 - frac)
        if measured_mean >= MIN_CAL_N and estimated_mean == estimated_mean:  # (not NaN)
            self.cal_n += 1
            self.cal_sum_sq += ((estimated_mean - measured_mean) / measured_mean) ** 2

    def relative_error(self) -> tuple[float, str]:
        """``(u, "residual" | "assumed")``: see the module docstring."""
        if self.cal_n >= MIN_CAL_TICKS:
            return math.sqrt(self.cal_sum_sq / self.cal_n), "residual"
        return ASSUMED_ERROR, "assumed"

    def figures(self, name: str, committed: float) -> dict[str, Any]:
        """The split of component ``name`` whose committed damage is now ``committed``;
        ``unattributed`` is what was committed after the last evaluated tick (its source
        mix is known when that tick ends)."""
        p = self.parts[name]
        u, how = self.relative_error()
        m = self.slopes[name]
        return {"measured": p["measured"], "estimated": p["estimated"],
                "unattributed": max(committed - p["measured"] - p["estimated"], 0.0),
                "estimated_low": p["estimated"] * max(1.0 - u, 0.0) ** m,
                "estimated_high": p["estimated"] * (1.0 + u) ** m,
                "estimate_relative_error": u, "estimate_error_from": how,
                "calibration_ticks": self.cal_n}

    def state(self) -> dict[str, Any]:
        return {"parts": {n: dict(p) for n, p in self.parts.items()}, "cal_n": self.cal_n,
                "cal_sum_sq": self.cal_sum_sq}
