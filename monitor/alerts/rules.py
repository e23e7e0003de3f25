"""Alert rules: one class per rule kind, each applied to one component, stream or the cable.

Every rule instance runs the same firing state machine (:meth:`Rule.step`) on sensor time:

* a tick where the condition holds starts a *pending* period; the alert fires at the first
  tick at least ``on_delay_s`` after the first tick of that period (at once when 0);
* while firing, a tick where the condition is gone starts a *clearing* period; the alert
  clears at the first tick at least ``off_delay_s`` after its start (at once when 0); a tick
  where the condition holds again cancels the clearing;
* a tick without data for the rule (no tension samples, NaN figures, component or stream
  absent) changes nothing;
* an operator reset releases a firing alert at the next tick (event ``"reset"``) and re-arms
  the rule; the condition is evaluated again from the tick after.

Subclasses only say what they observe (:meth:`Rule.observe`, returning the value shown in the
alert) and when the condition holds (:meth:`Rule.holds`). They must stay cheap: the replay of a
30-day log evaluates ~260 k ticks, so the no-change path is a few attribute reads and compares.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, Mapping

import numpy as np

from monitor.alerts.config import RuleConfig
from monitor.alerts.records import decode_float, encode_float
from monitor.events import Observation

NS = 1_000_000_000
_NO_ENTRIES = np.zeros((0, 3), np.int64)  # an empty window (RejectedRate.window): read only


class TickStats:
    """Per-tick aggregates several rules share, computed at most once per tick."""

    __slots__ = ("obs", "_tmax", "_tmin")

    def __init__(self, obs: Observation) -> None:
        self.obs = obs
        self._tmin, self._tmax = obs.tension_range_N or (None, None)

    @property
    def tension_max(self) -> float:
        if self._tmax is None:
            x = self.obs.tension_N
            self._tmax = float(x.max()) if len(x) else math.nan
        return self._tmax

    @property
    def tension_min(self) -> float:
        if self._tmin is None:
            x = self.obs.tension_N
            self._tmin = float(x.min()) if len(x) else math.nan
        return self._tmin


class Rule:
    """One alert instance: a configured rule applied to one target (component/stream/cable)."""

    kind = ""
    unit = ""
    latching = False

    def __init__(self, cfg: RuleConfig, target: str) -> None:
        self.cfg = cfg
        self.name = cfg.name
        self.target = target
        self.severity = cfg.severity
        p = cfg.params
        self.threshold = float(p.get("threshold", math.nan))
        self.on_delay_ns = int(round(p.get("on_delay_s", 0.0) * NS))
        self.off_delay_ns = int(round(p.get("off_delay_s", 0.0) * NS))
        # firing state machine (times in sensor ns; -1 = not set)
        self.firing = False
        self.pending_since_ns = -1
        self.clear_since_ns = -1
        self.starts_at_ns = -1
        self.last_sent_ns = -1
        self.value = math.nan
        self.reset_pending = False
        self.acked_by = ""
        self.ack_reason = ""

    # --- what subclasses define -------------------------------------------------------------
    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        """The rule's value for this tick, or None when the tick has no data for it (NaN is
        the only value unequal to itself: the subclasses test ``value == value`` inline, since
        a helper call per rule per tick is a measurable share of a replay's alert ticks)."""
        raise NotImplementedError

    def holds(self, value: float) -> bool:
        """Whether the alert condition holds for ``value`` (may use ``self.firing``)."""
        raise NotImplementedError

    def summary(self) -> str:
        """One-line explanation for the alert annotations."""
        raise NotImplementedError

    @property
    def threshold_value(self) -> float:
        """The limit shown with the value (same unit as the value)."""
        return self.threshold

    def on_reset(self) -> None:
        """Re-arm after an operator reset (latching rules re-baseline here)."""

    def extra_state(self) -> dict[str, Any]:
        return {}

    def set_extra_state(self, d: Mapping[str, Any]) -> None:
        pass

    # --- the shared state machine ----------------------------------------------------------
    def step(self, obs: Observation, tick: TickStats) -> str | None:
        """Advance to tick ``obs.t_ns``; return "fire", "clear", "reset" (a firing alert
        released by an operator reset), "rearm" (a reset of a quiet rule) or None."""
        value = self.observe(obs, tick)
        if value is None:
            return None
        self.value = value
        if self.reset_pending:
            # the caller emits the release record, then calls on_reset() to re-arm
            self.reset_pending = False
            was_firing = self.firing
            self.firing = False
            self.pending_since_ns = self.clear_since_ns = -1
            return "reset" if was_firing else "rearm"
        if self.holds(value):
            if self.firing:
                self.clear_since_ns = -1
                return None
            t = obs.t_ns
            if self.pending_since_ns < 0:
                self.pending_since_ns = t
            if t - self.pending_since_ns >= self.on_delay_ns:
                self.firing = True
                self.starts_at_ns = t
                self.clear_since_ns = -1
                return "fire"
            return None
        if not self.firing:
            self.pending_since_ns = -1
            return None
        if self.latching:
            return None
        t = obs.t_ns
        if self.clear_since_ns < 0:
            self.clear_since_ns = t
        if t - self.clear_since_ns >= self.off_delay_ns:
            self.firing = False
            self.pending_since_ns = self.clear_since_ns = -1
            return "clear"
        return None

    def get_state(self) -> dict[str, Any]:
        return {
            "firing": self.firing, "pending_since_ns": self.pending_since_ns,
            "clear_since_ns": self.clear_since_ns, "starts_at_ns": self.starts_at_ns,
            "last_sent_ns": self.last_sent_ns, "value": encode_float(self.value),
            "reset_pending": self.reset_pending, "acked_by": self.acked_by,
            "ack_reason": self.ack_reason, "extra": self.extra_state(),
        }

    def set_state(self, d: Mapping[str, Any]) -> None:
        self.firing = bool(d["firing"])
        self.pending_since_ns = int(d["pending_since_ns"])
        self.clear_since_ns = int(d["clear_since_ns"])
        self.starts_at_ns = int(d["starts_at_ns"])
        self.last_sent_ns = int(d["last_sent_ns"])
        self.value = decode_float(d["value"])
        self.reset_pending = bool(d["reset_pending"])
        self.acked_by = str(d["acked_by"])
        self.ack_reason = str(d["ack_reason"])
        self.set_extra_state(d.get("extra", {}))


class DamageFraction(Rule):
    """Accumulated Miner damage of a component reached ``threshold`` (a Miner sum, 1 = failure).

    Latches: the Miner sum only grows, so the alert stays active until an operator reset
    (which re-baselines: the rule then counts damage accumulated after the reset) or a cable
    replacement, seen as the committed damage going down (the pipeline restarted the
    accumulator), which releases the alert and counts from zero again.
    """

    kind = "damage_fraction"
    latching = True

    def __init__(self, cfg: RuleConfig, target: str) -> None:
        super().__init__(cfg, target)
        self.baseline = 0.0
        self.last_committed = 0.0
        self._replaced = False  # set and consumed within one step

    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        comp = obs.components.get(self.target)
        if comp is None:
            return None
        committed = comp.damage_committed
        if committed < self.last_committed:  # accumulator restarted: cable replaced
            self.reset_pending = True
            self._replaced = True
        self.last_committed = committed
        value = comp.damage
        return value if value == value else None

    def holds(self, value: float) -> bool:
        return value - self.baseline >= self.threshold

    def on_reset(self) -> None:
        # after a replacement the new accumulator starts from zero; after an operator reset
        # only damage accumulated from now on counts towards the threshold
        self.baseline = 0.0 if self._replaced else self.value
        self._replaced = False

    @property
    def threshold_value(self) -> float:
        return self.baseline + self.threshold

    def summary(self) -> str:
        return (f"accumulated fatigue damage (Miner sum) of {self.target} reached "
                f"{self.threshold:g}{' since the last reset' if self.baseline else ''}; "
                "latched until an operator reset or cable replacement")

    def extra_state(self) -> dict[str, Any]:
        return {"baseline": self.baseline, "last_committed": self.last_committed}

    def set_extra_state(self, d: Mapping[str, Any]) -> None:
        self.baseline = float(d["baseline"])
        self.last_committed = float(d["last_committed"])


class DamageRate(Rule):
    """Damage rate of a component (Miner sum per day over the pipeline's rate window) above
    ``threshold``, with on- and off-delays."""

    kind = "damage_rate"
    unit = "1/d"

    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        comp = obs.components.get(self.target)
        if comp is None:
            return None
        value = comp.damage_rate_per_day
        return value if value == value else None

    def holds(self, value: float) -> bool:
        return value > self.threshold

    def summary(self) -> str:
        return (f"fatigue damage rate of {self.target} above {self.threshold:g} per day "
                f"(life used up in under {1 / self.threshold:.4g} days at this rate)")


class RemainingLife(Rule):
    """Remaining life of a component (days at the current damage rate) below ``threshold``."""

    kind = "remaining_life"
    unit = "d"

    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        comp = obs.components.get(self.target)
        if comp is None:
            return None
        value = comp.remaining_life_days
        return value if value == value else None

    def holds(self, value: float) -> bool:
        return value < self.threshold

    def summary(self) -> str:
        return f"remaining fatigue life of {self.target} below {self.threshold:g} days"


class TensionHigh(Rule):
    """Peak tension in a tick above ``threshold`` x ``breaking_strength_N``.

    Fires after ``on_delay_s``; clears only when the peak falls below
    ``(threshold - deadband)`` x breaking strength, so a load hovering at the limit does not
    flap.
    """

    kind = "tension_high"
    unit = "N"

    def __init__(self, cfg: RuleConfig, target: str) -> None:
        super().__init__(cfg, target)
        mbl = cfg.params["breaking_strength_N"]
        self.on_level = self.threshold * mbl
        self.off_level = (self.threshold - cfg.params["deadband"]) * mbl

    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        value = tick.tension_max
        return value if value == value else None

    def holds(self, value: float) -> bool:
        return value >= self.off_level if self.firing else value > self.on_level

    @property
    def threshold_value(self) -> float:
        return self.on_level

    def summary(self) -> str:
        mbl = self.cfg.params['breaking_strength_N'] / 1e3
        if self.threshold >= 1.0:  # the line would have parted, or the load is not real
            return f"line load above breaking strength ({mbl:g} kN)"
        return f"cable tension above {self.threshold:.0%} of the breaking strength ({mbl:g} kN)"


class _ConductorStressAbove(Rule):
    """Peak conductor stress in a tick above ``threshold`` x a reference stress of the
    component (``reference_Pa``); subclasses name the reference and say what it means."""

    unit = "Pa"

    def __init__(self, cfg: RuleConfig, target: str, reference_Pa: float) -> None:
        super().__init__(cfg, target)
        self.reference_Pa = reference_Pa
        self.level = self.threshold * reference_Pa

    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        comp = obs.components.get(self.target)
        if comp is None:
            return None
        value = comp.max_stress_Pa
        return value if value == value else None

    def holds(self, value: float) -> bool:
        return value > self.level

    @property
    def threshold_value(self) -> float:
        return self.level


class ConductorStress(_ConductorStressAbove):
    """Peak conductor stress in a tick above ``threshold`` x the component's (derated)
    endurance stress."""

    kind = "conductor_stress"

    def summary(self) -> str:
        return (f"conductor stress of {self.target} above {self.threshold:g} x its derated "
                f"endurance stress ({self.reference_Pa / 1e6:.4g} MPa)")


class ConductorYield(_ConductorStressAbove):
    """Peak conductor stress in a tick above ``threshold`` x the stress at which the hot spot
    (scf x stress) reaches the conductor's tensile yield: the elastic helix model and the S-N
    curve do not hold there, so the damage figures are underestimates."""

    kind = "conductor_yield"

    def summary(self) -> str:
        return (f"elastic model beyond yield: damage underestimated ({self.target} above "
                f"{self.threshold:g} x its yield stress, {self.reference_Pa / 1e6:.4g} MPa "
                "nominal)")


class SlackSnap(Rule):
    """A snatch load: tension below ``floor_N`` (slack) followed, within ``window_s`` of the
    last slack sample, by a sample at least ``threshold`` N above the floor.

    The value is the peak snap tension of the tick (0 when none); the alert clears after
    ``off_delay_s`` without a new snap. The time of the last slack sample carries across ticks.
    """

    kind = "slack_snap"
    unit = "N"

    def __init__(self, cfg: RuleConfig, target: str) -> None:
        super().__init__(cfg, target)
        self.floor = cfg.params["floor_N"]
        self.snap_level = self.floor + self.threshold
        self.window_ns = int(round(cfg.params["window_s"] * NS))
        self.last_slack_ns = -1

    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        t, x = obs.load_t_ns, obs.tension_N
        if len(t) == 0:
            return None
        recent = self.last_slack_ns >= 0 and int(t[0]) - self.last_slack_ns <= self.window_ns
        if not recent and tick.tension_min >= self.floor:
            return 0.0  # no slack now or recently: nothing can snap (the cheap, usual path)
        slack = x < self.floor
        last_slack = np.maximum.accumulate(np.where(slack, t, np.int64(-1)))
        last_slack = np.maximum(last_slack, self.last_slack_ns)
        snap = (x >= self.snap_level) & (last_slack >= 0) & (t - last_slack <= self.window_ns)
        if slack.any():
            self.last_slack_ns = int(last_slack[-1])
        return float(x[snap].max()) if snap.any() else 0.0

    def holds(self, value: float) -> bool:
        return value >= self.snap_level

    @property
    def threshold_value(self) -> float:
        return self.snap_level

    def summary(self) -> str:
        return (f"snatch load: cable went slack (below {self.floor / 1e3:g} kN) then jumped "
                f"by at least {self.threshold / 1e3:g} kN within "
                f"{self.window_ns / NS:g} s")

    def extra_state(self) -> dict[str, Any]:
        return {"last_slack_ns": self.last_slack_ns}

    def set_extra_state(self, d: Mapping[str, Any]) -> None:
        self.last_slack_ns = int(d["last_slack_ns"])


class Stale(Rule):
    """A sensor stream flagged stale by the pipeline (no accepted sample for longer than the
    stream's ``stale_after_s``). The value is the data age in seconds (inf if never seen)."""

    kind = "stale"
    unit = "s"

    def __init__(self, cfg: RuleConfig, target: str) -> None:
        super().__init__(cfg, target)
        self._stale = False

    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        s = obs.streams.get(self.target)
        if s is None:
            return None
        self._stale = s.stale
        return (obs.t_ns - s.last_t_ns) / NS if s.last_t_ns > 0 else math.inf

    def holds(self, value: float) -> bool:
        return self._stale

    def summary(self) -> str:
        return f"sensor stream {self.target} is stale (no accepted samples)"


class RejectedRate(Rule):
    """Fraction of a stream's received samples rejected by validation over the last
    ``window_s`` of sensor time above ``threshold`` (copies, ``duplicate``, are neither:
    monitor.validate)."""

    kind = "rejected_rate"
    unit = ""

    def __init__(self, cfg: RuleConfig, target: str) -> None:
        super().__init__(cfg, target)
        self.window_ns = int(round(cfg.params["window_s"] * NS))
        # the window's entries (t_ns, rejected, received), oldest first: a deque, or (after
        # the replay batch, monitor.alerts.batch, moved the window) rows of an int64 array
        # turned into the deque only when something reads it
        self._ticks: deque[tuple[int, int, int]] | None = deque()
        self._held = np.zeros((0, 3), np.int64)
        self.rejected = 0
        self.received = 0

    @property
    def ticks(self) -> deque[tuple[int, int, int]]:
        """The window's entries (t_ns, rejected, received), oldest first."""
        if self._ticks is None:
            self._ticks = deque(map(tuple, self._held.tolist()))
        return self._ticks

    @ticks.setter
    def ticks(self, entries: deque[tuple[int, int, int]]) -> None:
        self._ticks = entries

    def window(self) -> np.ndarray:
        """The window's entries as rows of an int64 array."""
        if self._ticks is None:
            return self._held
        if not self._ticks:  # (an idle stream's, every slab)
            return _NO_ENTRIES
        return np.array(self._ticks, np.int64).reshape(len(self._ticks), 3)

    def set_window(self, entries: np.ndarray, rejected: int, received: int) -> None:
        """Set the window to ``entries`` (rows t_ns, rejected, received) and its totals."""
        self._ticks, self._held = None, entries
        self.rejected, self.received = rejected, received

    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        s = obs.streams.get(self.target)
        if s is None:
            return None
        t = obs.t_ns
        ticks = self.ticks
        if s.received_in_tick:
            ticks.append((t, s.rejected_in_tick, s.received_in_tick))
            self.rejected += s.rejected_in_tick
            self.received += s.received_in_tick
        horizon = t - self.window_ns
        while ticks and ticks[0][0] <= horizon:
            _, rej, rec = ticks.popleft()
            self.rejected -= rej
            self.received -= rec
        return self.rejected / self.received if self.received else None

    def holds(self, value: float) -> bool:
        return value > self.threshold

    def summary(self) -> str:
        return (f"more than {self.threshold:.1%} of {self.target} samples rejected over the "
                f"last {self.window_ns / NS:g} s")

    def extra_state(self) -> dict[str, Any]:
        return {"ticks": [list(x) for x in self.ticks]}

    def set_extra_state(self, d: Mapping[str, Any]) -> None:
        self.ticks = deque((int(a), int(b), int(c)) for a, b, c in d["ticks"])
        self.rejected = sum(x[1] for x in self.ticks)
        self.received = sum(x[2] for x in self.ticks)


class ModelResidual(Rule):
    """Measured and motion-estimated tension (tick means) differ by more than ``threshold`` N
    for ``on_delay_s``: the load cell or the estimator model is wrong."""

    kind = "model_residual"
    unit = "N"

    def observe(self, obs: Observation, tick: TickStats) -> float | None:
        value = abs(obs.measured_tension_N - obs.estimated_tension_N)
        return value if value == value else None

    def holds(self, value: float) -> bool:
        return value > self.threshold

    def summary(self) -> str:
        return (f"measured and estimated tension differ by more than "
                f"{self.threshold / 1e3:g} kN")


RULE_CLASSES: Mapping[str, type[Rule]] = {
    cls.kind: cls
    for cls in (DamageFraction, DamageRate, RemainingLife, TensionHigh, ConductorStress,
                ConductorYield, SlackSnap, Stale, RejectedRate, ModelResidual)
}
