"""``buoymon alerts list|ack|reset|outbox``: inspect and manage alerts.

Two targets:

* a running daemon, over Zenoh (``--buoy ID [--connect ENDPOINT]``, or by default the buoy
  and endpoints of ``--config``, itself by default ``/etc/buoymon/buoymon.toml``): ``list`` queries
  ``buoy/<id>/monitor/alerts``; ``ack``/``reset`` send the command as the payload of a query on
  ``buoy/<id>/monitor/alerts/operator`` and print the daemon's answer once it has applied it;
  when the configuration's daemon does not answer, ``list`` reads its checkpoint (``[state]
  path``) and says so, ``ack``/``reset`` name the ``--state`` that would act on it;
* a saved state for when the daemon is stopped (``--state PATH``): the daemon's checkpoint
  (SQLite, ``[state] path``) or a replay's JSON state file (``buoymon replay --state``), whose
  ``"alerts"`` key holds the alert engine state; ``ack``/``reset`` rewrite it atomically, and a
  reset is applied at the first tick after the daemon restarts. (A running daemon would
  overwrite its checkpoint: talk to it with ``--buoy`` instead.)

Every ack and reset records who, when (wall-clock time of the command) and why in the engine's
history.

``outbox`` works on the delivery outbox (``[alerts.outbox] path`` of ``--config``, or
``--outbox PATH``), also while the daemon runs: per channel what is pending, delivered,
retried, dropped, and the dead letters (messages a receiver refused, with its answer);
``--retry-dead`` queues them again (after fixing the receiver), ``--discard-dead`` deletes
them. While dead letters are held the daemon raises ``alert_delivery_refused``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from monitor.alerts.engine import AlertEngine
from monitor.atomic_file import atomic_write_text
from monitor.daemon_target import DEFAULT_CONFIG, DEFAULT_CONNECT, endpoint_arg, load_target


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("alerts",
                              description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="alerts_command", metavar="ACTION", required=True)

    def target(sp: argparse.ArgumentParser) -> None:
        g = sp.add_mutually_exclusive_group()
        g.add_argument("--state", type=Path, help="checkpoint (SQLite) of a stopped daemon, or "
                       "a replay's JSON state file")
        g.add_argument("--buoy", help="buoy id of a running daemon (reached over Zenoh)")
        g.add_argument("--config", metavar="CFG.toml",
                       help="the running daemon's configuration: its [buoy] id and [zenoh] "
                            f"endpoints (the default, {DEFAULT_CONFIG}, when neither --state "
                            "nor --buoy is given)")
        sp.add_argument("--connect", action="append", metavar="ENDPOINT", type=endpoint_arg,
                        help=f"Zenoh endpoint of the daemon (default {DEFAULT_CONNECT}, or the "
                             "configuration's); repeatable")
        sp.add_argument("--timeout", type=float, default=10.0,
                        help="seconds to wait for the daemon (default 10)")
        sp.add_argument("--json", action="store_true", help="print JSON instead of a table")

    ls = sub.add_parser("list", help="list active alerts")
    target(ls)
    ack = sub.add_parser("ack", help="acknowledge an active alert (stops its re-sends)")
    ack.add_argument("fingerprint")
    reset = sub.add_parser("reset", help="release and re-arm a rule (e.g. a latched damage "
                                         "alert after an inspection or cable replacement)")
    reset.add_argument("rule")
    reset.add_argument("component")
    for sp in (ack, reset):
        sp.add_argument("--who", required=True, help="operator name")
        sp.add_argument("--why", required=True, help="reason, recorded in the alert history")
        target(sp)
    ob = sub.add_parser("outbox", help="delivery outbox: pending, delivered, dead letters")
    ob.add_argument("--outbox", type=Path, help="outbox database (default: [alerts.outbox] "
                                                 "path of --config)")
    ob.add_argument("--config", metavar="CFG.toml",
                    help=f"configuration naming the outbox (default {DEFAULT_CONFIG})")
    act = ob.add_mutually_exclusive_group()
    act.add_argument("--retry-dead", action="store_true", help="queue the dead letters again")
    act.add_argument("--discard-dead", action="store_true", help="delete the dead letters")
    ob.add_argument("--json", action="store_true", help="print JSON instead of text")
    ob.set_defaults(func=run_outbox)
    p.set_defaults(func=run)


def run_outbox(args: argparse.Namespace) -> int:
    """``buoymon alerts outbox``: see the module docstring."""
    from monitor.alerts.outbox import Outbox  # noqa: PLC0415

    try:
        path = args.outbox if args.outbox is not None else _outbox_path(args.config)
        if not Path(path).is_file():
            raise ValueError(f"{path}: no outbox database there (alerts not yet delivered "
                             "through webhook, e-mail or Alertmanager?)")
        box = Outbox(str(path), {})
    except (ValueError, OSError) as exc:
        print(f"buoymon alerts outbox: {exc}", file=sys.stderr)
        return 1
    try:
        settled = (box.settle_dead(retry=True) if args.retry_dead
                   else box.settle_dead(retry=False) if args.discard_dead else None)
        result = {"outbox": str(path), "channels": box.stats(),
                  "dead_letters": box.messages(dead_only=True)}
    finally:
        box.close()
    if settled is not None:
        result["settled"] = settled
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    for ch, st in result["channels"].items():
        print(f"{ch}: {st['pending']} pending, {st['delivered_total']} delivered, "
              f"{st['failures_total']} failed attempts, {st['dropped_total']} dropped, "
              f"{st['dead_letters']} dead letters")
    for d in result["dead_letters"]:
        when = datetime.fromtimestamp(d["dead_s"], tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S")
        print(f"  dead {d['channel']} {d['dedup_key']} (refused {when} UTC): {d['last_error']}")
    if settled is not None:
        print(f"{settled} dead letter(s) {'queued again' if args.retry_dead else 'discarded'}")
    return 0


def _outbox_path(config: str | None) -> Path:
    from monitor.alerts.config import AlertsConfig  # noqa: PLC0415
    from monitor.schema import read_toml  # noqa: PLC0415

    path = Path(config or DEFAULT_CONFIG)
    out = Path(AlertsConfig.from_dict(read_toml(path).get("alerts")).outbox.path)
    return out if out.is_absolute() else Path.cwd() / out


def _command(args: argparse.Namespace) -> dict[str, Any] | None:
    if args.alerts_command == "list":
        return None
    # when the operator acted (wall clock): recorded in the history, not used for evaluation
    base = {"who": args.who, "why": args.why, "at_ns": time.time_ns()}
    if args.alerts_command == "ack":
        return {"op": "ack", "fingerprint": args.fingerprint, **base}
    return {"op": "reset", "rule": args.rule, "component": args.component, **base}


def run(args: argparse.Namespace) -> int:
    try:
        try:
            result = _run(args)
        except ValueError as exc:
            raise _explain_live_ack(args, exc) from None
    except (ValueError, OSError, TimeoutError) as exc:
        print(f"buoymon alerts: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(result, indent=2, allow_nan=False))
    elif args.alerts_command == "list":
        print(format_table(result["alerts"]))
    else:
        details = ", ".join(f"{k}={v}" for k, v in result.items()
                            if k not in ("ok", "op", "alert"))
        print(f"{args.alerts_command} done" + (f": {details}" if details else ""))
    return 0


def _explain_live_ack(args: argparse.Namespace, exc: ValueError) -> ValueError:
    """``exc``, or for an ack of a listed logger-clock alert (which only the engine's sensor-time
    alerts take) an error that says so instead of "no such alert"."""
    from monitor.alerts.live import LIVE_RULES  # noqa: PLC0415

    if args.alerts_command != "ack" or "no such alert" not in str(exc):
        return exc
    try:
        listed = _run(argparse.Namespace(**{**vars(args), "alerts_command": "list"}))["alerts"]
    except (ValueError, OSError, TimeoutError):
        return exc
    for a in listed:
        if a.get("fingerprint") == args.fingerprint and a.get("rule") in LIVE_RULES:
            return ValueError(f"fingerprint {args.fingerprint!r}: a logger-clock alert "
                              f"({a['rule']}), raised by the daemon's own health rules; it cannot "
                              "be acknowledged and clears when its cause does (docs/DAEMON.md)")
    return exc


def _run(args: argparse.Namespace) -> dict[str, Any]:
    """The list, or the command's result, from the daemon or the state file."""
    if args.state is not None:
        result = _on_state_file(args.state, _command(args))
    else:
        if not 0 < args.timeout < math.inf:
            raise ValueError(f"--timeout {args.timeout}: must be a number of seconds > 0")
        buoy, connect, state_path = args.buoy, [DEFAULT_CONNECT], None
        if buoy is None:  # the buoy (and endpoints) of the daemon's configuration
            target = load_target(args.config or DEFAULT_CONFIG)
            buoy, connect = target.buoy_id, list(target.connect)
            state_path = Path(target.state_path) if target.state_path else None
        try:
            result = _on_daemon(buoy, args.connect or connect, args.timeout, _command(args))
        except TimeoutError as exc:
            if state_path is None or not state_path.exists():
                raise
            if args.alerts_command != "list":  # a stopped daemon's checkpoint, on request
                raise TimeoutError(f"{exc}; if the daemon is stopped, --state "
                                   f"{state_path} acts on its checkpoint") from None
            # listing reads, as `buoymon status` does: the stopped daemon's checkpoint
            print(f"buoymon alerts: {exc}: daemon NOT RUNNING? the alerts of its last "
                  f"checkpoint ({state_path}) follow", file=sys.stderr)
            result = _on_state_file(state_path, None)
    return result


def format_table(alerts: list[dict[str, Any]]) -> str:
    """Active alerts as an aligned text table."""
    if not alerts:
        return "no active alerts"
    from monitor.alerts.live import LIVE_RULES  # noqa: PLC0415 (a table to print)

    # live rules run on the logger's clock, the others on sensor time (docs/DAEMON.md)
    header = ("FINGERPRINT", "SEVERITY", "RULE", "COMPONENT",
              "SINCE (UTC; sensor time, * logger clock)", "VALUE", "THRESHOLD", "ACKED BY")
    rows = [header] + [(
        a["fingerprint"], a["severity"], a["rule"], a["labels"]["component"],
        datetime.fromtimestamp(a["starts_at_ns"] / 1e9, tz=timezone.utc).strftime(
            "%Y-%m-%d %H:%M:%S") + (" *" if a["rule"] in LIVE_RULES else ""),
        a["annotations"]["value"], a["annotations"]["threshold"], a["acked_by"] or "-",
    ) for a in alerts]
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)


def _on_state_file(path: Path, command: dict[str, Any] | None) -> dict[str, Any]:
    with open(path, "rb") as f:
        checkpoint = f.read(16) == b"SQLite format 3\x00"
    if checkpoint:
        from monitor.checkpoint import CheckpointStore

        store = CheckpointStore(path)
        try:
            saved = store.load()
            if saved is None or not isinstance(saved.state, dict) \
                    or not isinstance(saved.state.get("pipeline"), dict):
                raise ValueError(f"{path}: the daemon checkpoint holds no pipeline state yet")
            outer = saved.state
            daemon = outer.get("daemon") or {}
            live = (daemon.get("live") or {}).get("firing") or []
            if command is None:  # the live (logger-clock) rules' alerts are listed too
                # a configuration without alert rules keeps no engine: live alerts only
                result = _apply(outer["pipeline"], path, None)[0] \
                    if "alerts" in outer["pipeline"] else {
                        "buoy": (daemon.get("last_status") or {}).get("buoy_id"), "alerts": []}
                result["alerts"] += [a for a in live if isinstance(a, dict)]
                return result
            result, changed = _apply(outer["pipeline"], path, command)
            if changed:
                store.save(outer)
            return result
        finally:
            store.close()
    try:
        state = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: neither a daemon checkpoint nor a JSON state file "
                         f"({exc})") from None
    result, changed = _apply(state, path, command)
    if changed:
        atomic_write_text(path, json.dumps(state, allow_nan=False))
    return result


def _apply(state: Any, path: Path, command: dict[str, Any] | None
           ) -> tuple[dict[str, Any], bool]:
    """List the alerts of a pipeline state, or apply ``command`` to it in place."""
    if not isinstance(state, dict) or "alerts" not in state:
        raise ValueError(f"{path}: state has no \"alerts\" entry")
    engine = AlertEngine.from_state(state["alerts"])
    if command is None:
        return {"buoy": engine.buoy_id, "alerts": [r.to_dict() for r in engine.active()]}, False
    result = engine.apply_command(command)
    state["alerts"] = engine.state()
    return result, True


def _on_daemon(buoy: str, connect: list[str], timeout: float,
               command: dict[str, Any] | None) -> dict[str, Any]:
    import zenoh

    from monitor.alerts.delivery import alerts_key, operator_key, peer_config

    key = alerts_key(buoy) if command is None else operator_key(buoy)
    payload = None if command is None else json.dumps(command)
    deadline = time.monotonic() + timeout
    with zenoh.open(peer_config(connect=connect)) as session:
        # right after connecting, the daemon's queryables may not be known yet: a query then
        # ends at once without replies, so ask again until the deadline (a query that reached
        # the daemon is answered, so a command is never applied twice)
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no answer from buoy {buoy!r} on {key} via {connect} "
                                   f"within {timeout:g} s")
            for reply in session.get(key, payload=payload, timeout=remaining):
                if reply.ok is None:
                    raise ValueError(f"daemon error: {reply.err.payload.to_string()}")
                result = json.loads(reply.ok.payload.to_bytes())
                if command is not None and not result.get("ok"):
                    raise ValueError(result.get("error", "command refused"))
                return result
            time.sleep(0.1)
