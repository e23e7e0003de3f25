"""``buoymon status``: one screen of a running daemon's status (or of its last checkpoint).

Asks the daemon over Zenoh (a query on ``buoy/<id>/monitor/status``, answered with the status
document it last published). With the daemon stopped (nothing answers on its endpoints), it
reads the state file (``[state] path``, the SQLite checkpoint), which holds the status of the
last checkpoint, and says so.
"""

from __future__ import annotations

import argparse
import json
import math
import sqlite3
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping, Sequence

from monitor.daemon_target import DEFAULT_CONFIG, DaemonTarget, endpoint_arg, load_target
from monitor.viz.human import remaining_life_text


def register(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = sub.add_parser("status",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", default=DEFAULT_CONFIG, metavar="CFG.toml",
                   help=f"the daemon's configuration (default {DEFAULT_CONFIG})")
    p.add_argument("--buoy", help="buoy id (default: [buoy] id of the configuration)")
    p.add_argument("--connect", action="append", metavar="ENDPOINT", type=endpoint_arg,
                   help="Zenoh endpoint of the daemon (default: its [zenoh] listen endpoints)")
    p.add_argument("--timeout", type=float, default=1.0,
                   help="seconds to wait for the daemon before reading the state file "
                        "(default 1)")
    p.add_argument("--json", action="store_true", help="print the status document as JSON")
    p.add_argument("--watch", action="store_true", help="refresh every second until Ctrl-C")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        target = load_target(args.config)
        if args.buoy:
            target = DaemonTarget(args.buoy, target.connect, target.state_path, target.origin)
        if args.connect:
            target = DaemonTarget(target.buoy_id, tuple(args.connect), target.state_path,
                                  "--connect")
        if not 0 < args.timeout < math.inf:
            raise ValueError(f"--timeout {args.timeout}: must be a number of seconds > 0")
        while True:
            source, doc = fetch(target, args.timeout)
            text = (json.dumps(_json_doc(source, doc), indent=2, allow_nan=False)
                    if args.json else render(source, doc))
            if not args.watch:
                print(text)
                return 0
            print("\x1b[H\x1b[2J" + text, flush=True)  # home and clear: one screen
            time.sleep(1.0)
    except BrokenPipeError:
        raise  # stdout's reader went away: monitor.cli ends quietly
    except (ValueError, OSError) as exc:
        print(f"buoymon status: {exc}", file=sys.stderr)
        return 1


def _json_doc(source: str, doc: Mapping[str, Any]) -> dict[str, Any]:
    """``--json``: whether the daemon answered, and when a stopped one was last seen."""
    if source == "daemon":
        return {"source": source, "running": True, "status": doc}
    return {"source": source, "running": False, "last_seen": _iso(doc["saved_ns"]),
            "last_seen_age_s": doc["checkpoint"]["age_s"], "status": doc}


def fetch(target: DaemonTarget, timeout: float) -> tuple[str, dict[str, Any]]:
    """(``"daemon"`` or ``"state file"``, status document)."""
    doc = query_daemon(target, timeout)
    if doc is not None:
        return "daemon", doc
    asked = f"no daemon answered at {', '.join(target.connect)} ({target.origin}) within " \
            f"{timeout:g} s"
    if target.state_path is None:
        raise ValueError(f"{asked}; a bridge configuration names no state file: pass the "
                         "daemon's configuration for its last checkpoint")
    try:
        return "state file", read_state_file(target.state_path)
    except ValueError as exc:  # say first that the daemon did not answer (busy, or stopped)
        raise ValueError(f"{asked}, and {exc}") from None


def query_daemon(target: DaemonTarget, timeout: float) -> dict[str, Any] | None:
    """The running daemon's status, or None if nothing answers within ``timeout``."""
    import zenoh  # noqa: PLC0415 (not needed for --help)

    from monitor import zenoh_io  # noqa: PLC0415
    from monitor.daemon_config import ZenohConfig  # noqa: PLC0415

    zc = ZenohConfig(mode="client", listen=(), connect=target.connect)
    deadline = time.monotonic() + timeout
    try:
        session = zenoh_io.open_session(zc)
    except zenoh.ZError:  # nothing listens there: the daemon is not running
        return None
    with session:
        key = zenoh_io.status_key(target.buoy_id)
        while (remaining := deadline - time.monotonic()) > 0:
            for reply in session.get(key, timeout=remaining):
                if reply.ok is not None:
                    return json.loads(reply.ok.payload.to_bytes())
            time.sleep(0.05)  # right after connecting the queryable may not be known yet
    return None


def read_state_file(path: str) -> dict[str, Any]:
    """The status saved with the last checkpoint (read-only: the file is not touched)."""
    if not Path(path).exists():
        raise ValueError(f"there is no state file at {path} ([state] path)")
    from monitor.checkpoint import decode_checkpoint  # noqa: PLC0415

    db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        row = db.execute("SELECT seq, saved_ns, state FROM checkpoint WHERE id = 1").fetchone()
    except sqlite3.Error as exc:
        raise ValueError(f"{path}: not a daemon checkpoint ({exc})") from None
    finally:
        db.close()
    if row is None:
        raise ValueError(f"{path}: the checkpoint is empty (the daemon never saved)")
    state = decode_checkpoint(path, row[0], row[2])
    doc = dict((state.get("daemon") or {}).get("last_status") or {})
    if not doc:
        raise ValueError(f"{path}: checkpoint {row[0]} holds no status (written before any "
                         "status, or by an older version)")
    age_s = (time.time_ns() - row[1]) / 1e9
    doc["checkpoint"] = {**doc.get("checkpoint", {}), "seq": row[0], "age_s": age_s}
    doc["saved_ns"] = row[1]
    # the saved health is how the daemon was then; a daemon that does not answer is not ok
    doc["health"] = {"ok": False, "reasons": [
        f"daemon not running: last seen {_t(row[1])} (its last checkpoint), {age_s:.0f} s ago"],
        "at_last_checkpoint": doc.get("health")}
    return doc


def _t(ns: Any) -> str:
    if not ns:
        return "-"
    return datetime.fromtimestamp(ns / 1e9, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


def _iso(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _n(x: Any, fmt: str = "{:.4g}", unit: str = "") -> str:
    return "-" if x is None else fmt.format(x) + unit


def _table(rows: Sequence[Sequence[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]


def render(source: str, doc: Mapping[str, Any]) -> str:
    """One screen of text for a status document."""
    out = []
    buoy = doc.get("buoy_id")
    if source == "daemon":
        up = _n(doc.get("uptime_s"), "{:.0f}", " s")
        out.append(f"buoy {buoy}: daemon RUNNING, up {up}, status at "
                   f"{_t(doc.get('wall_time_ns'))}")
    else:
        age = _n(doc["checkpoint"]["age_s"], "{:.0f}", " s")
        out.append(f"buoy {buoy}: daemon NOT RUNNING (no answer); last seen "
                   f"{_t(doc.get('saved_ns'))} (its last checkpoint), {age} ago; the figures "
                   "below are as of then")
    health = doc.get("health") or {}
    if "at_last_checkpoint" in health:  # a stopped daemon: its saved health is history
        then = health["at_last_checkpoint"] or {}
        out.append("health: NOT RUNNING (at the last checkpoint: "
                   f"{'ok' if then.get('ok', True) else 'FAILING'})"
                   + "".join(f"\n  {r}" for r in then.get("reasons", [])))
    else:
        out.append(f"health: {'ok' if health.get('ok', True) else 'FAILING'}"
                   + "".join(f"\n  {r}" for r in health.get("reasons", [])))
    age = _n(doc.get("fatigue_feed_age_s"), "{:.1f}", " s")
    # the age counts from the start while nothing has fed fatigue (the fatigue_blind rule)
    fed = (f"fatigue not fed yet ({age} since the start)"
           if "load_t_ns" in doc and doc["load_t_ns"] is None else f"fatigue fed {age} ago")
    out.append(f"sensor time {_t(doc.get('now_ns'))}; load source {doc.get('load_source')}; "
               + fed)
    rows: list[tuple[str, ...]] = [
        ("STREAM", "AGE", "RATE", "ACCEPTED", "REJECTED", "MISSED", "CLOCK")]
    for name, s in sorted((doc.get("streams") or {}).items()):
        rej = s.get("rejected") or {}
        rejected = " ".join(f"{k}={v}" for k, v in sorted(rej.items()) if v) or "0"
        clock = []
        if s.get("clock_skew_s") is not None:
            clock.append(f"skew {s['clock_skew_s']:+.3g} s")
        if s.get("time_behind_s"):
            clock.append(f"RESTARTED {s['time_behind_s']:.6g} s back")
        stale = " STALE" if s.get("data_stale") and s.get("data_age_s") is not None else ""
        rows.append((name, _n(s.get("data_age_s"), "{:.1f}", " s") + stale,
                     _n(s.get("rate_hz"), "{:.1f}", " Hz"), str(s.get("accepted", 0)), rejected,
                     str(s.get("samples_missed", "-")), ", ".join(clock) or "-"))
    out += ["streams:", *_table(rows)]
    rows = [("COMPONENT", "DAMAGE", "COMMITTED", "RATE/DAY", "REMAINING LIFE", "BEYOND YIELD")]
    beyond = []
    for name, c in sorted((doc.get("components") or {}).items()):
        n_yield = c.get("samples_beyond_yield")
        rows.append((str(name), _n(c.get("damage")), _n(c.get("damage_committed")),
                     _n(c.get("damage_rate_per_day")),
                     # in words, as the report: "6.5 h", "more than 1,000 years"
                     "-" if c.get("remaining_life_days") is None
                     else remaining_life_text(float(c["remaining_life_days"])),
                     _n(n_yield, "{:.0f}")))
        if n_yield:
            beyond.append(str(name))
    out += ["components:", *_table(rows)]
    if beyond:  # the elastic helix model and the S-N curve do not hold there (docs/CONDUCTOR.md)
        out.append(f"elastic model beyond yield: damage underestimated ({', '.join(beyond)})")
    sources = (doc.get("bridge") or {}).get("sources") or {}
    if sources:  # the instruments read by a bridge (docs/SENSORS.md)
        rows = [("SOURCE", "STATE", "LAST LINE", "LINES", "SAMPLES", "REJECTED")]
        for name, b in sorted(sources.items()):
            rej = " ".join(f"{k}={v}" for k, v in sorted((b.get("rejected") or {}).items()))
            rows.append((f"{name} ({b.get('transport')} -> {b.get('sensor')})",
                         str(b.get("state")).upper() if b.get("state") != "reading"
                         else "reading", _n(b.get("last_line_age_s"), "{:.1f}", " s ago"),
                         str(b.get("lines", 0)), str(b.get("samples", 0)), rej or "0"))
        out += ["bridge:", *_table(rows)]
    active = (doc.get("alerts") or {}).get("active", [])
    out.append(f"active alerts{'' if source == 'daemon' else ' at the last checkpoint'}: "
               f"{len(active)}")
    if active:
        out += _table([("SEVERITY", "RULE", "COMPONENT", "SOURCE", "SUMMARY")] + [
            (a["severity"], a["rule"], a["component"], a["source"], a["summary"])
            for a in active])
    ck = doc.get("checkpoint") or {}
    out.append(f"checkpoint: seq {ck.get('seq')}, {_n(ck.get('age_s'), '{:.1f}', ' s')} old"
               + (f", FAILING ({ck.get('failures')} failures): {ck.get('last_error')}"
                  if ck.get("failing") else ""))
    channels = (doc.get("delivery") or {}).get("channels") or {}
    out.append("outbox: " + (", ".join(
        f"{ch} {c.get('pending', '?')} pending" + _stuck(c)
        + (f", {c['dead_letters']} dead letters" if c.get("dead_letters") else "")
        for ch, c in sorted(channels.items())) or "no webhook/e-mail channel"))
    out.append(f"queue depth {doc.get('queue_depth', '-')}")
    return "\n".join(out)


def _stuck(channel: dict) -> str:
    """How long the oldest waiting message has waited (a receiver down shows as more than
    "N pending": every attempt failing since then)."""
    age = channel.get("oldest_pending_age_s")
    return ("" if not channel.get("pending") or age is None else
            f" (oldest {age:.0f} s, {channel.get('failures_total', 0)} failed attempts)")
