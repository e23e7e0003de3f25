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

from models._jit import kernel

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

    def ticks(self, committed: Mapping[str, Sequence[float] | np.ndarray],
              rows: Sequence[tuple[int, int, float, float]] | np.ndarray) -> None:
        """Evaluated ticks in time order: each component's committed damage at each tick's
        end, and per tick ``(measured samples, samples, mean measured tension, mean
        estimate)`` (the means NaN when absent)."""
        names = list(committed)
        parts = np.array([[self.parts[n]["committed"], self.parts[n]["measured"],
                           self.parts[n]["estimated"]] for n in names], dtype=np.float64)
        cal = np.array([self.cal_n, self.cal_sum_sq], dtype=np.float64)
        _split_ticks(np.asarray(rows, dtype=np.float64).reshape(-1, 4),
                     np.array([committed[n] for n in names], dtype=np.float64), parts, cal)
        for name, (c, m, e) in zip(names, parts.tolist()):
            self.parts[name].update(committed=c, measured=m, estimated=e)
        self.cal_n, self.cal_sum_sq = int(cal[0]), float(cal[1])

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


@kernel()
def _split_ticks(rows, committed, parts, cal):  # pragma: no cover - compiled
    """:meth:`DamageSplit.ticks` over arrays: ``rows`` (ticks, 4), ``committed``
    (components, ticks); ``parts`` (components: committed, measured, estimated) and ``cal``
    (ticks calibrated on, sum of squares) are updated in place. Every sum runs left to
    right, one tick after the other (a pairwise sum would change the last bits with the
    split of the ticks into slabs)."""
    k = rows.shape[0]
    for c in range(committed.shape[0]):
        last = parts[c, 0]
        measured = parts[c, 1]
        estimated = parts[c, 2]
        for i in range(k):
            n = rows[i, 1]
            frac = rows[i, 0] / n if n > 0 else 0.0
            delta = committed[c, i] - last
            if delta < 0:
                delta = 0.0  # (a reset)
            last = committed[c, i]
            measured += delta * frac
            estimated += delta * (1.0 - frac)
        parts[c, 0] = last
        parts[c, 1] = measured
        parts[c, 2] = estimated
    for i in range(k):
        meas = rows[i, 2]
        est = rows[i, 3]
        if meas >= MIN_CAL_N and not np.isnan(est):
            rel = (est - meas) / meas
            cal[0] += 1.0
            cal[1] += rel * rel
