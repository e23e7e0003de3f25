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
from typing import Any, Mapping, Sequence

import numpy as np

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

    def ticks(self, committed: Mapping[str, Sequence[float]],
              rows: Sequence[tuple[int, int, float, float]]) -> None:
        """Evaluated ticks in time order: each component's committed damage at each tick's
        end, and per tick ``(measured samples, samples, mean measured tension, mean
        estimate)`` (the means NaN when absent)."""
        n_meas, n, meas, est = (np.array(c, dtype=np.float64) for c in zip(*rows))
        frac = np.divide(n_meas, n, out=np.zeros_like(n), where=n > 0)
        for name, values in committed.items():
            p = self.parts[name]
            v = np.array(values, dtype=np.float64)
            delta = np.diff(v, prepend=p["committed"])
            delta[delta < 0] = 0.0  # (a reset)
            p["committed"] = float(v[-1])
            # sequential sums (a cumulative sum adds in order, as a loop would): the same
            # figures for any split of the ticks into slabs
            p["measured"] = _running_sum(p["measured"], delta * frac)
            p["estimated"] = _running_sum(p["estimated"], delta * (1.0 - frac))
        with np.errstate(invalid="ignore", divide="ignore"):
            cal = (meas >= MIN_CAL_N) & ~np.isnan(est)
            rel = (est[cal] - meas[cal]) / meas[cal]
        self.cal_n += int(rel.shape[0])
        self.cal_sum_sq = _running_sum(self.cal_sum_sq, rel * rel)

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


def _running_sum(start: float, terms: np.ndarray) -> float:
    """``start + terms[0] + terms[1] + ...`` added left to right (np.sum would add pairwise,
    so a split of the terms would change the last bits)."""
    if terms.shape[0] == 0:
        return start
    return float(np.cumsum(np.concatenate(([start], terms)))[-1])
