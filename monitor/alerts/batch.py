"""Alert evaluation of many ticks at once: the replay path of :class:`~monitor.alerts.engine.
AlertEngine` (issue 22: one Python call per rule per tick was a quarter of a replay's CPU).

The pipeline hands the figures of a slab's ticks as arrays (:class:`TickInputs`); each rule
instance becomes a row of per-tick values (NaN where the tick has no data for it) and a
condition code, built by numpy (and a compiled pass over the load samples for slack snaps).
:func:`scan_ticks` then runs the firing state machine of :meth:`Rule.step` and the engine's
re-send test over the ticks in one compiled loop and stops at the first tick where a rule
would change state: a transition, a pending reset, a cable replacement, or a tick the
caller marks (a forecast due). That tick is evaluated the ordinary way
(:meth:`AlertEngine.evaluate` on an Observation), so every transition record is built by
the same code as in the live path; the quiet ticks before it only moved pending/clearing
times, each rule's last value and the re-send times, which :meth:`TickBatch.sync` writes
into the rule objects first. Their re-sends (a firing rule's record again, every
``resend_interval_s``: most of the records of a long replay) are built from the rule and
its value at that tick by the engine's own ``_record``, with no Observation.

Bit-identity with the per-tick path holds because each row is the value its rule's
``observe`` computes, by the same IEEE operations (tests/test_alerts_batch.py runs both).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from operator import attrgetter
from typing import TYPE_CHECKING, Callable, Literal, Mapping

import numpy as np

from models._jit import kernel
from monitor.alerts.rules import (NS, ConductorStress, ConductorYield, DamageFraction,
                                  DamageRate, ModelResidual, RejectedRate, RemainingLife, Rule,
                                  SlackSnap, Stale, TensionHigh)

if TYPE_CHECKING:
    from monitor.alerts.engine import AlertEngine
    from monitor.alerts.records import AlertRecord

NO_DUE = np.iinfo(np.int64).max  # no forecast due: scan_ticks never stops for one

# condition codes of scan_ticks: value > on, value < on, value >= on, hysteresis (>= off
# while firing, > on otherwise), value - baseline >= on (damage fraction), a given flag
_ABOVE, _BELOW, _AT_LEAST, _HYSTERESIS, _ABOVE_BASELINE, _FLAG = range(6)


@dataclass(frozen=True, eq=False)
class StreamTicks:
    """One sensor stream's health at each tick end, as the per-tick ``StreamObs``."""

    last_t_ns: np.ndarray  # int64, 0 when no accepted sample yet
    stale: np.ndarray  # bool
    received: np.ndarray  # int64, samples received in the tick
    rejected: np.ndarray  # int64, samples rejected in the tick


@dataclass(frozen=True, eq=False)
class TickInputs:
    """What the rules observe at each of ``ends.shape[0]`` consecutive tick ends, as arrays
    (NaN where the per-tick Observation has NaN). ``component(name, i)`` is a component's
    figure ``i`` of the per-tick ComponentObs (0 damage, 1 committed, 2 rate per day,
    3 remaining life days, 4 peak stress); it, ``stream(name)`` and ``load()`` (load samples
    ``t, v`` and each tick's ``starts, stops`` in them) are asked only for what the rules
    need. ``receives(name)`` (optional) is False when the stream can have received no
    sample in these ticks: a rejected-rate rule with an empty window then has no value
    without asking ``stream``."""

    buoy_id: str
    ends: np.ndarray  # int64
    tension_max: np.ndarray
    measured: np.ndarray
    estimated: np.ndarray
    component: Callable[[str, int], np.ndarray]
    stream: Callable[[str], StreamTicks]
    load: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
    receives: Callable[[str], bool] | None = None


@kernel(inline="always")
def _holds(mode, v, on, off, firing, baseline, flag):
    """Whether a rule's condition holds for value ``v`` (the subclasses' ``holds``)."""
    if mode == 0:
        return v > on
    if mode == 1:
        return v < on
    if mode == 2:
        return v >= on
    if mode == 3:
        return v >= off if firing else v > on
    if mode == 4:
        return v - baseline >= on
    return flag != 0


# columns of scan_ticks's per-rule arrays: ``kind`` (int64) and ``level`` (float64) hold
# what a rule is, ``state`` (int64) its firing state (a batch reloads it after each tick
# evaluated the ordinary way); one array each, since every argument of a compiled call costs
_MODE, _ON_DELAY, _OFF_DELAY, _LATCHING = range(4)
_ON, _OFF, _BASELINE = range(3)
_FIRING, _PENDING, _CLEAR, _LAST_SENT, _RESET_PENDING, _ACKED, _LAST_DATA = range(7)


@kernel()
def scan_ticks(ends, values, flags, kind, level, resend_ns, stop, due_ns, j0, state, sent):
    """Run :meth:`Rule.step` and the engine's re-send test for every rule (row of ``kind``,
    ``level``, ``state``, ``values``, ``flags``) from tick ``j0`` on; return the first tick
    where one would return an event (or ``stop`` is set, or the tick ends at or after
    ``due_ns``), the tick count when none, and how many re-sends the ticks before it made.
    Those ticks are applied: the pending and clearing times in ``state`` move as in
    ``step``, its ``_LAST_DATA`` column is the last tick with a value per rule, and each
    re-send due is a row (tick, rule, the rule's last data tick then) of ``sent`` with the
    last-sent time moved to its tick, in the engine's order (tick by tick, rule by rule);
    nothing else can change on them."""
    n = ends.shape[0]
    rules = kind.shape[0]
    m = 0
    for j in range(j0, n):
        t = ends[j]
        if stop[j] or t >= due_ns:
            return j, m
        for r in range(rules):  # a transition at this tick? (changes nothing)
            v = values[r, j]
            if v == v:
                if state[r, _RESET_PENDING]:
                    return j, m
                firing = state[r, _FIRING]
                if _holds(kind[r, _MODE], v, level[r, _ON], level[r, _OFF], firing,
                          level[r, _BASELINE], flags[r, j]):
                    if not firing:
                        p = state[r, _PENDING] if state[r, _PENDING] >= 0 else t
                        if t - p >= kind[r, _ON_DELAY]:
                            return j, m
                elif firing and not kind[r, _LATCHING]:
                    c = state[r, _CLEAR] if state[r, _CLEAR] >= 0 else t
                    if t - c >= kind[r, _OFF_DELAY]:
                        return j, m
        for r in range(rules):  # none: the pending and clearing times move, re-sends go
            v = values[r, j]
            firing = state[r, _FIRING]
            if v == v:
                state[r, _LAST_DATA] = j
                if _holds(kind[r, _MODE], v, level[r, _ON], level[r, _OFF], firing,
                          level[r, _BASELINE], flags[r, j]):
                    if firing:
                        state[r, _CLEAR] = -1
                    elif state[r, _PENDING] < 0:
                        state[r, _PENDING] = t
                elif not firing:
                    state[r, _PENDING] = -1
                elif not kind[r, _LATCHING] and state[r, _CLEAR] < 0:
                    state[r, _CLEAR] = t
            if (resend_ns and firing and not state[r, _ACKED]
                    and t - state[r, _LAST_SENT] >= resend_ns):
                sent[m, 0] = j
                sent[m, 1] = r
                sent[m, 2] = state[r, _LAST_DATA]
                m += 1
                state[r, _LAST_SENT] = t
    return n, m


@kernel()
def slack_snap_ticks(t, x, starts, stops, floor, snap_level, window_ns, last_slack):
    """:meth:`SlackSnap.observe` over consecutive ticks: each tick's peak snap tension (0 when
    none, NaN without samples) and the time of the last slack sample after it."""
    n = starts.shape[0]
    values = np.empty(n)
    after = np.empty(n, np.int64)
    last = last_slack
    for k in range(n):
        if stops[k] == starts[k]:
            values[k] = np.nan
        else:
            peak = -np.inf
            found = False
            for i in range(starts[k], stops[k]):
                xi = x[i]
                if xi < floor and t[i] > last:
                    last = t[i]
                if xi >= snap_level and last >= 0 and t[i] - last <= window_ns:
                    if not found or xi > peak:
                        peak = xi
                    found = True
            values[k] = peak if found else 0.0
        after[k] = last
    return values, after


@kernel()
def rejected_rate_ticks(held, ends, received, rejected, window_ns):
    """:meth:`RejectedRate.observe` over consecutive ticks, from the window entries the rule
    holds (``held``: rows t, rejected, received): each tick's rate (NaN without samples in
    the window), and the window after it as rows ``lo..hi-1`` of the returned entries with
    its totals. Counts are integers below 2**53, so the quotient is observe's (Python's
    correctly rounded int / int)."""
    n, m = ends.shape[0], held.shape[0]
    entries = np.empty((m + n, 3), np.int64)
    n_rej, n_rec = 0, 0
    for i in range(m):
        entries[i] = held[i]
        n_rej += held[i, 1]
        n_rec += held[i, 2]
    values = np.empty(n)
    lo_at = np.empty(n, np.int64)
    hi_at = np.empty(n, np.int64)
    rej_at = np.empty(n, np.int64)
    rec_at = np.empty(n, np.int64)
    lo, hi = 0, m
    for k in range(n):
        t = ends[k]
        if received[k]:
            entries[hi, 0] = t
            entries[hi, 1] = rejected[k]
            entries[hi, 2] = received[k]
            hi += 1
            n_rej += rejected[k]
            n_rec += received[k]
        horizon = t - window_ns
        while lo < hi and entries[lo, 0] <= horizon:
            n_rej -= entries[lo, 1]
            n_rec -= entries[lo, 2]
            lo += 1
        values[k] = n_rej / n_rec if n_rec else np.nan
        lo_at[k], hi_at[k], rej_at[k], rec_at[k] = lo, hi, n_rej, n_rec
    return values, entries, lo_at, hi_at, rej_at, rec_at


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels now, on empty input."""
    f, i = np.zeros(0), np.zeros(0, np.int64)
    slack_snap_ticks(i, f, i, i, 0.0, 0.0, 0, -1)
    rejected_rate_ticks(np.zeros((0, 3), np.int64), i, i, i, 0)
    scan_ticks(i, np.zeros((0, 0)), np.zeros((0, 0), np.uint8), np.zeros((0, 4), np.int64),
               np.zeros((0, 3)), 0, np.zeros(0, bool), NO_DUE, 0, np.zeros((0, 7), np.int64),
               np.zeros((0, 3), np.int64))


class _Row:
    """One rule instance over a slab: its values and flags per tick, and how to bring the
    rule object to the end of tick ``j`` (``side``; its value through ``value_at``, else
    the row's value there)."""

    __slots__ = ("values", "flags", "side", "value_at")

    def __init__(self, values: np.ndarray, flags: np.ndarray | None = None,
                 side: Callable[[int], None] | None = None,
                 value_at: Callable[[int], float] | None = None) -> None:
        self.values, self.flags, self.side, self.value_at = values, flags, side, value_at


def _damage_fraction(rule: DamageFraction, x: TickInputs, stop: np.ndarray,
                     seen: set[int]) -> _Row:
    committed = x.component(rule.target, 1)
    # the accumulator restarted (committed damage went down): replacement, a reset tick
    stop[0] |= committed[0] < rule.last_committed
    if id(committed) not in seen:  # (components counting together share the column)
        seen.add(id(committed))
        stop[1:] |= committed[1:] < committed[:-1]

    def side(j: int) -> None:
        rule.last_committed = float(committed[j])
    return _Row(x.component(rule.target, 0), side=side)


def _component_figure(column: int) -> Callable[..., _Row]:
    def build(rule: Rule, x: TickInputs, stop: np.ndarray, seen: set[int]) -> _Row:
        return _Row(x.component(rule.target, column))
    return build


def _tension_high(rule: TensionHigh, x: TickInputs, stop: np.ndarray, seen: set[int]) -> _Row:
    return _Row(x.tension_max)


def _model_residual(rule: ModelResidual, x: TickInputs, stop: np.ndarray,
                    seen: set[int]) -> _Row:
    return _Row(np.abs(x.measured - x.estimated))


def _slack_snap(rule: SlackSnap, x: TickInputs, stop: np.ndarray, seen: set[int]) -> _Row:
    t, v, starts, stops = x.load()
    values, after = slack_snap_ticks(t, v, starts, stops, float(rule.floor),
                                     float(rule.snap_level), rule.window_ns, rule.last_slack_ns)

    def side(j: int) -> None:
        rule.last_slack_ns = int(after[j])
    return _Row(values, side=side)


def _stale(rule: Stale, x: TickInputs, stop: np.ndarray, seen: set[int]) -> _Row:
    s = x.stream(rule.target)
    ends = x.ends

    def value_at(j: int) -> float:  # as observe: Python's int / int, correctly rounded
        last = int(s.last_t_ns[j])
        return (int(ends[j]) - last) / NS if last > 0 else math.inf
    return _Row(np.zeros(ends.shape[0]), s.stale, value_at=value_at)


def _rejected_rate(rule: RejectedRate, x: TickInputs, stop: np.ndarray,
                   seen: set[int]) -> _Row:
    held = rule.window()
    if not held.shape[0] and (x.receives is not None and not x.receives(rule.target)
                              or not x.stream(rule.target).received.any()):
        # an empty window staying empty (an idle stream): no rate at any tick
        return _Row(np.full(x.ends.shape[0], math.nan))
    s = x.stream(rule.target)
    values, entries, lo, hi, n_rej, n_rec = rejected_rate_ticks(
        held, x.ends, s.received, s.rejected, rule.window_ns)

    def side(j: int) -> None:
        rule.set_window(entries[lo[j]:hi[j]], int(n_rej[j]), int(n_rec[j]))
    return _Row(values, side=side)


def _level(code: int, on: str, off: str | None = None) -> Callable[[Rule], tuple]:
    """A rule's condition: code, its level attribute and (hysteresis) its off level."""
    return lambda r: (code, float(getattr(r, on)), float(getattr(r, off)) if off else math.nan)


# per rule class: its condition (scan_ticks's code and levels) and its row builder
_KINDS: Mapping[type, tuple[Callable[[Rule], tuple], Callable[..., _Row]]] = {
    DamageFraction: (_level(_ABOVE_BASELINE, "threshold"), _damage_fraction),
    DamageRate: (_level(_ABOVE, "threshold"), _component_figure(2)),
    RemainingLife: (_level(_BELOW, "threshold"), _component_figure(3)),
    ConductorStress: (_level(_ABOVE, "level"), _component_figure(4)),
    ConductorYield: (_level(_ABOVE, "level"), _component_figure(4)),
    TensionHigh: (_level(_HYSTERESIS, "on_level", "off_level"), _tension_high),
    SlackSnap: (_level(_AT_LEAST, "snap_level"), _slack_snap),
    Stale: (lambda r: (_FLAG, math.nan, math.nan), _stale),
    RejectedRate: (_level(_ABOVE, "threshold"), _rejected_rate),
    ModelResidual: (_level(_ABOVE, "threshold"), _model_residual),
}


class BatchPlan:
    """What does not change from slab to slab for an engine's rules: their condition codes,
    levels, delays and whether they latch (``kind``, ``level``: scan_ticks's arrays, the
    baselines aside), and the getter of their firing state."""

    @classmethod
    def of(cls, engine: "AlertEngine", rules: list[Rule]) -> "BatchPlan | Literal[False]":
        """The plan, False when a rule is of a kind this module does not scan (exactly: a
        subclass may observe differently)."""
        return all(type(r) in _KINDS for r in rules) and cls(engine, rules)

    def __init__(self, engine: "AlertEngine", rules: list[Rule]) -> None:
        self.engine, self.rules = engine, rules
        self.builders = [_KINDS[type(r)][1] for r in rules]
        levels = [_KINDS[type(r)][0](r) for r in rules]
        self.kind = np.array([(x[0], r.on_delay_ns, r.off_delay_ns, r.latching)
                              for x, r in zip(levels, rules)], np.int64).reshape(len(rules), 4)
        self.level = np.array([(x[1], x[2], 0.0) for x in levels],
                              np.float64).reshape(len(rules), 3)
        # the rules with a baseline (damage fraction): it moves on a reset
        self.with_baseline = [i for i, r in enumerate(rules) if isinstance(r, DamageFraction)]
        self.firing_state = attrgetter("firing", "pending_since_ns", "clear_since_ns",
                                       "last_sent_ns", "reset_pending", "acked_by")
        self.index = np.arange(len(rules))
        self.flagged = [i for i, r in enumerate(rules) if isinstance(r, Stale)]  # (_stale's)


class TickBatch:
    """The rules of one engine over the ticks of ``inputs`` (:meth:`run`)."""

    def __init__(self, plan: BatchPlan, inputs: TickInputs) -> None:
        engine, n = plan.engine, inputs.ends.shape[0]
        if n and int(inputs.ends[0]) <= engine.last_t_ns:
            raise ValueError(f"tick t_ns={int(inputs.ends[0])} is not after the previous "
                             f"evaluation ({engine.last_t_ns}); alert ticks must advance")
        self.plan, self.engine, self.rules, self.ends = plan, engine, plan.rules, inputs.ends
        self.stop = np.zeros(n, bool)
        seen: set[int] = set()
        self.rows = rows = [build(r, inputs, self.stop, seen)
                            for build, r in zip(plan.builders, plan.rules)]
        self.values = np.array([row.values for row in rows], np.float64).reshape(len(rows), n)
        self.flags = np.zeros((len(rows), n), np.uint8)
        for i in plan.flagged:
            flags = rows[i].flags
            assert flags is not None  # (a stale rule's row has them)
            self.flags[i] = flags
        self.level = plan.level.copy()  # (the baselines are the rules')
        self.sent = np.empty((len(rows) * n, 3), np.int64)  # at most one per rule and tick
        self.reload()

    def run(self, tick: Callable[[int], None], sent: Callable[[list[AlertRecord]], None],
            quiet: Callable[[int, int], None] | None = None,
            next_due: Callable[[], int | None] | None = None) -> None:
        """Evaluate every tick: ``tick(k)`` must pass the ``k``-th tick's Observation to
        :meth:`AlertEngine.evaluate` (and may do more), and is called only for ticks where
        something happens or that end at or after ``next_due()``; ``quiet(a, b)`` is told
        of each run of ticks ``a..b-1`` in between, in order, and ``sent`` gets the re-sends
        those ticks made (the records :meth:`AlertEngine.evaluate` would have returned
        there), before the next ``tick``."""
        j, n = 0, self.ends.shape[0]
        while True:
            due = next_due() if next_due is not None else None
            stop, m = self.scan(j, NO_DUE if due is None else due)
            if quiet is not None and stop > j:
                quiet(j, stop)
            if m:
                sent(self._resends(m))
            if stop == n:
                break
            self.sync(stop)
            tick(stop)
            self.reload()
            j = stop + 1
        self.sync(n)

    def scan(self, j0: int, due_ns: int) -> tuple[int, int]:
        """Apply the quiet ticks from ``j0`` on; return the first that is not (or the count)
        and how many re-sends they made (rows of ``self.sent``)."""
        stop, m = scan_ticks(self.ends, self.values, self.flags, self.plan.kind, self.level,
                             self.engine._resend_ns, self.stop, due_ns, j0, self.state,
                             self.sent)
        return int(stop), int(m)

    def _value(self, r: int, j: int) -> float:
        """Rule ``r``'s value at tick ``j`` (its row's, or as its ``value_at`` says)."""
        row = self.rows[r]
        return float(self.values[r, j]) if row.value_at is None else row.value_at(j)

    def _resends(self, m: int) -> list[AlertRecord]:
        """The records of the first ``m`` re-sends of the last scan, each with its rule's
        value as of its tick (the rule objects are otherwise as then: a re-send needs a
        firing rule, and its record reads nothing a quiet tick moves)."""
        out = []
        for j, r, d in self.sent[:m].tolist():
            rule = self.rules[r]
            if d >= 0:  # else the value before the scan: the rule's own
                rule.value = self._value(r, d)
            out.append(self.engine._record(rule, "resend", int(self.ends[j])))
        return out

    def sync(self, j: int) -> None:
        """Bring the rule objects and the engine to the end of tick ``j - 1``."""
        if j == 0:
            return
        state = self.state
        last_data = state[:, _LAST_DATA]
        # every rule's row value at its last data tick, in one step (-1: none, unused)
        at = self.values[self.plan.index, last_data].tolist()
        for rule, row, (_, pending, clear, last_sent, _, _, d), v in zip(
                self.rules, self.rows, state.tolist(), at):
            rule.pending_since_ns, rule.clear_since_ns = pending, clear
            rule.last_sent_ns = last_sent
            if d >= 0:
                rule.value = v if row.value_at is None else row.value_at(d)
            if row.side is not None:
                row.side(j - 1)
        self.engine.last_t_ns = int(self.ends[j - 1])

    def reload(self) -> None:
        """Take the rules' firing state from the rule objects (after an ordinary tick)."""
        self.state = np.array(
            [(f, p, c, s, reset, acked != "", -1)
             for f, p, c, s, reset, acked in map(self.plan.firing_state, self.rules)],
            np.int64).reshape(len(self.rules), 7)
        rules = self.rules
        for i in self.plan.with_baseline:
            self.level[i, _BASELINE] = rules[i].baseline  # type: ignore[attr-defined]
