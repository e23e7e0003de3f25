"""The alert engine: evaluates every configured rule on each sensor-time tick.

The pipeline builds one :class:`monitor.events.Observation` per tick (``[alerts]
eval_interval_s`` of sensor time) and calls :meth:`AlertEngine.evaluate`, which returns only
what changed: alerts that fired, cleared or were released by a reset, plus re-sends of active,
unacknowledged alerts every ``resend_interval_s`` of sensor time. Nothing reads the wall clock,
so a replay and the live daemon produce identical histories for the same samples. A slab of
many ticks with no per-tick hook (a replay) goes through :meth:`AlertEngine.tick_batch`
instead (:mod:`monitor.alerts.batch`), which calls :meth:`AlertEngine.evaluate` only at the
ticks where something happens, with the same results.

Operator actions (:meth:`AlertEngine.ack`, :meth:`AlertEngine.reset`) are recorded in the
history with who, when (``at_ns``, as given by the caller) and why. A reset takes effect at
the next evaluated tick, so its release is emitted on sensor time like every other transition.

:meth:`AlertEngine.state` is plain JSON (no NaN/inf literals) and self-contained (it embeds
the alerts config and component endurance stresses), so ``buoymon alerts --state`` can load
it without the TOML file; ``from_state(state())`` continues bit-exactly.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, Iterable, Literal, Mapping

from monitor.alerts.batch import BatchPlan, TickBatch, TickInputs
from monitor.alerts.config import CABLE_COMPONENT, KIND_PARAMS, AlertsConfig, RuleConfig
from monitor.alerts.records import AlertRecord
from monitor.alerts.rules import NS, RULE_CLASSES, ConductorStress, ConductorYield, Rule, TickStats
from monitor.blocks import SENSOR_FIELDS, validate_buoy_id
from monitor.events import Observation
from monitor.schema import error, unknown

STATE_VERSION = 1


def _endurance(name: str, info: Any, key: str = "endurance_stress_Pa") -> float | None:
    """Endurance stress (Pa) of a component description, None if it has none.

    Accepts a number, None, a mapping with ``endurance_stress_Pa``, or any object with an
    ``endurance_stress_Pa`` attribute (e.g. the pipeline's component info). With
    ``key="yield_stress_Pa"`` the same for the yield stress (a bare number has none).
    """
    if info is None or isinstance(info, (int, float)) and not isinstance(info, bool):
        value = info if key == "endurance_stress_Pa" else None
    elif isinstance(info, Mapping):
        value = info.get(key)
    else:
        value = getattr(info, key, None)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"component {name!r}: {key} = {value!r}: must be a number")
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"component {name!r}: {key} = {value!r}: must be > 0")
    return float(value)


class AlertEngine:
    """Rule instances for one buoy, their firing state, and the alert history."""

    def __init__(self, config: AlertsConfig, buoy_id: str,
                 endurance_Pa: Mapping[str, float | None],
                 yield_Pa: Mapping[str, float | None] | None = None) -> None:
        self.config = config
        self.buoy_id = validate_buoy_id(buoy_id)
        self.endurance_Pa = dict(endurance_Pa)
        self.yield_Pa = {n: (yield_Pa or {}).get(n) for n in self.endurance_Pa}
        self._resend_ns = int(round(config.resend_interval_s * NS))
        self._rules: list[Rule] = []
        for rc in config.rules:
            self._rules.extend(self._instances(rc))
        self._by_fp: dict[str, Rule] = {}
        self._by_key: dict[tuple[str, str], Rule] = {}
        for r in self._rules:
            fp = self._record(r, "fire", 0).fingerprint
            if fp in self._by_fp:
                raise error(r.cfg.where, "name", r.name,
                            f"rule {r.name!r} for component {r.target!r} is also defined by "
                            f"{self._by_fp[fp].cfg.where}; give each rule a distinct name")
            self._by_fp[fp] = r
            self._by_key[(r.name, r.target)] = r
        self.last_t_ns = -1
        # what the batch path (tick_batch) needs of the rules, made on first use; False when
        # a rule is of a kind it does not scan
        self._batch_plan: BatchPlan | Literal[False] | None = None
        self._history: deque[dict[str, Any]] = deque(maxlen=config.history_limit)

    @classmethod
    def from_config(cls, alerts_cfg: Mapping[str, Any] | AlertsConfig, buoy_id: str,
                    components: Mapping[str, Any]) -> "AlertEngine":
        """Build from the ``[alerts]`` table (or a validated :class:`AlertsConfig`).

        ``components`` maps each fatigue component name to its description: anything with an
        ``endurance_stress_Pa`` (attribute or key; the derated endurance stress, None for
        non-conductor components), or that number itself; and optionally a
        ``yield_stress_Pa`` (the nominal stress at yield, for ``conductor_yield`` rules).
        """
        cfg = alerts_cfg if isinstance(alerts_cfg, AlertsConfig) else AlertsConfig.from_dict(alerts_cfg)
        return cls(cfg, buoy_id, {str(n): _endurance(str(n), c) for n, c in components.items()},
                   {str(n): _endurance(str(n), c, "yield_stress_Pa") for n, c in components.items()})

    def _instances(self, rc: RuleConfig) -> Iterable[Rule]:
        target_kind, _ = KIND_PARAMS[rc.kind]
        cls = RULE_CLASSES[rc.kind]
        if target_kind == "cable":
            return [cls(rc, rc.component or CABLE_COMPONENT)]
        if target_kind == "stream":
            if rc.component is not None and rc.component not in SENSOR_FIELDS:
                raise unknown(rc.where, "component", rc.component, SENSOR_FIELDS, "sensor stream",
                              rc.component)
            return [cls(rc, s) for s in ([rc.component] if rc.component else SENSOR_FIELDS)]
        if rc.component is not None and rc.component not in self.endurance_Pa:
            raise unknown(rc.where, "component", rc.component, self.endurance_Pa, "component",
                          rc.component)
        names = [rc.component] if rc.component else list(self.endurance_Pa)
        if cls not in (ConductorStress, ConductorYield):
            return [cls(rc, n) for n in names]
        levels, what = ((self.endurance_Pa, "endurance") if cls is ConductorStress
                        else (self.yield_Pa, "yield"))
        if rc.component is not None and levels[rc.component] is None:
            raise error(rc.where, "component", rc.component,
                        f"component has no {what} stress (not a conductor)")
        return [cls(rc, n, levels[n]) for n in names if levels[n] is not None]

    # --- evaluation ------------------------------------------------------------------------
    @property
    def eval_interval_s(self) -> float:
        return self.config.eval_interval_s

    def evaluate(self, obs: Observation) -> list[AlertRecord]:
        """Advance every rule to tick ``obs.t_ns``; return transitions and due re-sends."""
        if obs.buoy_id != self.buoy_id:
            raise ValueError(f"observation for buoy {obs.buoy_id!r} given to the alert engine "
                             f"of buoy {self.buoy_id!r}")
        t = int(obs.t_ns)
        if t <= self.last_t_ns:
            raise ValueError(f"observation t_ns={t} is not after the previous evaluation "
                             f"({self.last_t_ns}); alert ticks must advance in sensor time")
        self.last_t_ns = t
        tick = TickStats(obs)
        resend = self._resend_ns
        out: list[AlertRecord] = []
        for rule in self._rules:
            event = rule.step(obs, tick)
            if event is None:
                if (resend and rule.firing and not rule.acked_by
                        and t - rule.last_sent_ns >= resend):
                    out.append(self._record(rule, "resend", t))
                    rule.last_sent_ns = t
                continue
            if event != "rearm":
                rec = self._record(rule, event, t)
                out.append(rec)
                self._history.append({"type": "alert", **rec.to_dict()})
                rule.last_sent_ns = t
            if event != "fire":
                rule.acked_by = rule.ack_reason = ""
            if event in ("reset", "rearm"):
                rule.on_reset()
        return out

    def tick_batch(self, inputs: TickInputs) -> TickBatch | None:
        """The rules over many ticks at once (:mod:`monitor.alerts.batch`; the same results
        as :meth:`evaluate` at each), None when a rule is of a kind it does not scan."""
        if self._batch_plan is None:
            self._batch_plan = BatchPlan.of(self, self._rules)
        return TickBatch(self._batch_plan, inputs) if self._batch_plan else None

    def _record(self, rule: Rule, event: str, t: int) -> AlertRecord:
        firing = event in ("fire", "resend")
        return AlertRecord(
            rule=rule.name, kind=rule.kind, severity=rule.severity, buoy=self.buoy_id,
            component=rule.target, state="firing" if firing else "resolved", event=event,
            starts_at_ns=rule.starts_at_ns, ends_at_ns=0 if firing else t, at_ns=t,
            value=rule.value, threshold=rule.threshold_value, unit=rule.unit,
            summary=rule.summary(), acked_by=rule.acked_by, ack_reason=rule.ack_reason,
        )

    # --- queries and operator actions ------------------------------------------------------
    def active(self) -> list[AlertRecord]:
        """Records of all firing alerts (as of the last evaluated tick)."""
        return [self._record(r, "fire", max(self.last_t_ns, 0)) for r in self._rules if r.firing]

    def history(self) -> list[dict[str, Any]]:
        """Transitions (``type`` "alert", the record's dict) and operator actions (``type``
        "ack"/"reset"), oldest first, at most ``history_limit`` entries."""
        return list(self._history)

    def rule_keys(self) -> list[tuple[str, str]]:
        """(rule name, component) of every rule instance, in evaluation order."""
        return [(r.name, r.target) for r in self._rules]

    def rule_kinds(self) -> set[str]:
        """The kinds of rule configured (the pipeline computes some inputs only for them)."""
        return {r.kind for r in self._rules}

    @staticmethod
    def _operator(who: str, why: str, at_ns: int) -> None:
        for key, val in (("who", who), ("why", why)):
            if not isinstance(val, str) or not val.strip():
                raise ValueError(f"{key} = {val!r}: must be a non-empty string")
        if isinstance(at_ns, bool) or not isinstance(at_ns, int) or at_ns < 0:
            raise ValueError(f"at_ns = {at_ns!r}: must be a non-negative integer (ns since epoch)")

    def ack(self, fingerprint: str, who: str, why: str, at_ns: int) -> AlertRecord:
        """Acknowledge an active alert: no more re-sends until it resolves. Returns its record."""
        self._operator(who, why, at_ns)
        rule = self._by_fp.get(fingerprint)
        if rule is None:
            raise ValueError(f"fingerprint {fingerprint!r}: no such alert")
        if not rule.firing:
            raise ValueError(f"fingerprint {fingerprint!r}: alert {rule.name}/{rule.target} "
                             "is not active")
        rule.acked_by, rule.ack_reason = who, why
        self._history.append({"type": "ack", "fingerprint": fingerprint, "rule": rule.name,
                              "component": rule.target, "who": who, "why": why, "at_ns": at_ns})
        return self._record(rule, "fire", max(self.last_t_ns, 0))

    def reset(self, rule: str, component: str, who: str, why: str, at_ns: int) -> None:
        """Release (at the next tick) and re-arm one rule instance, e.g. a latched damage alert
        after an inspection or a cable replacement; a damage-fraction rule then counts only
        damage accumulated after the reset."""
        self._operator(who, why, at_ns)
        r = self._by_key.get((rule, component))
        if r is None:
            known = ", ".join(f"{n}/{c}" for n, c in self.rule_keys())
            raise ValueError(f"rule {rule!r} component {component!r}: no such rule instance "
                             f"(known: {known})")
        r.reset_pending = True
        fp = next(f for f, x in self._by_fp.items() if x is r)
        self._history.append({"type": "reset", "fingerprint": fp, "rule": rule,
                              "component": component, "who": who, "why": why, "at_ns": at_ns})

    def apply_command(self, cmd: Mapping[str, Any]) -> dict[str, Any]:
        """Apply an operator command dict (as sent by ``buoymon alerts ack|reset``):
        ``{"op": "ack", "fingerprint", "who", "why", "at_ns"}`` or
        ``{"op": "reset", "rule", "component", "who", "why", "at_ns"}``."""
        if not isinstance(cmd, Mapping):
            raise ValueError(f"operator command {cmd!r}: must be a JSON object")
        op = cmd.get("op")
        try:
            if op == "ack":
                rec = self.ack(cmd["fingerprint"], cmd["who"], cmd["why"], cmd["at_ns"])
                return {"ok": True, "op": op, "alert": rec.to_dict()}
            if op == "reset":
                self.reset(cmd["rule"], cmd["component"], cmd["who"], cmd["why"], cmd["at_ns"])
                return {"ok": True, "op": op, "rule": cmd["rule"], "component": cmd["component"]}
        except KeyError as exc:
            raise ValueError(f"operator command {op!r}: missing field {exc.args[0]!r}") from None
        raise ValueError(f"operator command op = {op!r}: must be \"ack\" or \"reset\"")

    # --- persistence -----------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """JSON-serialisable snapshot (strict JSON: no NaN/inf literals)."""
        return {
            "version": STATE_VERSION,
            "buoy_id": self.buoy_id,
            "config": self.config.to_dict(),
            "components": {n: e for n, e in self.endurance_Pa.items()},
            "yield_Pa": dict(self.yield_Pa),
            "last_t_ns": self.last_t_ns,
            "rules": {fp: {"kind": r.kind, **r.get_state()} for fp, r in self._by_fp.items()},
            "history": list(self._history),
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any],
                   alerts_cfg: Mapping[str, Any] | AlertsConfig | None = None,
                   buoy_id: str | None = None,
                   components: Mapping[str, Any] | None = None) -> "AlertEngine":
        """Rebuild from :meth:`state`. With ``alerts_cfg``/``buoy_id``/``components`` given
        (e.g. a daemon restarted with an edited TOML), those win and the saved state of every
        rule instance that still exists (same fingerprint and kind) is restored."""
        if not isinstance(state, Mapping) or state.get("version") != STATE_VERSION:
            raise ValueError(f"alert engine state: version must be {STATE_VERSION}, got "
                             f"{state.get('version') if isinstance(state, Mapping) else state!r}")
        try:
            eng = cls.from_config(
                alerts_cfg if alerts_cfg is not None else state["config"],
                buoy_id if buoy_id is not None else state["buoy_id"],
                components if components is not None else {
                    n: {"endurance_stress_Pa": e, "yield_stress_Pa": state.get("yield_Pa", {}).get(n)}
                    for n, e in state["components"].items()},
            )
            eng.last_t_ns = int(state["last_t_ns"])
            for fp, rs in state["rules"].items():
                rule = eng._by_fp.get(fp)
                if rule is not None and rule.kind == rs["kind"]:
                    rule.set_state(rs)
            eng._history.extend(state["history"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"alert engine state is missing or has a bad field: {exc!r}") from exc
        return eng
