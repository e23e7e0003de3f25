"""``buoymon record --config CFG -o DIR``: record a buoy's Zenoh traffic to MCAP.

Subscribes to everything under ``buoy/<id>/`` (sensors, status, alerts) and writes each
message byte for byte to hourly-rotated MCAP files in DIR (``[record]`` rotate_s and
flush_interval_s apply), until SIGTERM/SIGINT. Sensor topics get the log format's protobuf
schema, so the files replay with ``buoymon replay``; JSON topics get a jsonschema channel.
"""

from __future__ import annotations

import argparse
import json
import logging
import queue
import signal
import threading
import time
from typing import Any

import msgspec

from monitor.blocks import parse_sensor_topic, validate_buoy_id
from monitor.daemon_config import ZenohConfig, parse_daemon_sections
from monitor.recorder import JSON_OBJECT, McapRecorder
from monitor.schema import ConfigError, read_toml
from monitor.sequence import SequenceTracker
from monitor import zenoh_io

log = logging.getLogger("buoymon.record")

_FETCH_TIMEOUT_S = 5.0  # longest wait for a sensor publisher's cache
# publishers appearing within this of each other have their caches recorded together, in
# time order across streams (liveliness tokens arrive one by one)
_SETTLE_S = 0.5
# ...but for no longer than this after the first of them: a publisher that keeps reappearing
# (a flapping link) must not hold the live messages back from the recording indefinitely
_SETTLE_MAX_S = 2.0


def register(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = sub.add_parser("record", description=__doc__.split("\n\n")[1])
    p.add_argument("--config", required=True, metavar="CFG.toml", help="configuration file")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output directory")
    p.set_defaults(func=run)


def client_side(zc: ZenohConfig) -> ZenohConfig:
    """The recorder joins the daemon's network as a client: it connects to the configured
    endpoints (the daemon's listen endpoints when none are given to connect to) and listens on
    nothing. A client because a Zenoh peer does not forward between other peers: as a peer
    the recorder would miss what peer publishers (``buoymon simulate --publish``, sensor
    drivers) send to the daemon."""
    return msgspec.structs.replace(zc, mode="client", listen=(), connect=zc.connect or zc.listen)


def recorder_token_key(buoy_id: str) -> str:
    return f"buoy/{validate_buoy_id(buoy_id)}/recorder/alive"


def record(buoy_id: str, zc: ZenohConfig, recorder: McapRecorder,
           stop: threading.Event, codec: zenoh_io.BlockCodec) -> int:
    """Record until ``stop`` is set; returns the number of messages written.

    Sensor messages are taken by their publishers' sequence numbers
    (:class:`monitor.sequence.SequenceTracker`, in memory): when sensor publishers appear
    (at start too) their whole caches are recorded, and a gap in the numbers is filled from
    the cache first, so a recorder restarted within the cache window loses nothing (what it
    recorded before is recorded again; a replay rejects the duplicate samples). The caches
    of publishers appearing within ``_SETTLE_S`` of each other (for at most ``_SETTLE_MAX_S``)
    are recorded together in sensor-time order, the messages arriving meanwhile after them: one stream's hour after
    another's was out of order by up to the cache's length, beyond a replay's reorder
    window (``late`` messages; as the daemon's catch-up, :mod:`monitor.daemon`)."""
    q: "queue.SimpleQueue[tuple]" = queue.SimpleQueue()
    seqs = SequenceTracker()
    with zenoh_io.open_session(zc) as session:
        sub = zenoh_io.declare_enqueuing_subscriber(session, f"buoy/{buoy_id}/**", q)
        watch = zenoh_io.declare_publisher_watch(session, buoy_id, q)
        # tells the shore (and tests) that this buoy's traffic is being recorded
        token = session.liveliness().declare_token(recorder_token_key(buoy_id))

        appeared: dict[tuple[str, str], None] = {}  # publishers whose caches are due
        held: list[tuple] = []  # what arrived while they were due
        due = 0.0  # monotonic time: _SETTLE_S after the last of them appeared (capped)
        settle_ends = 0.0  # _SETTLE_MAX_S after the first of them appeared

        def take(item: tuple) -> None:
            nonlocal due, settle_ends
            if item[0] == "publisher":
                now = time.monotonic()
                if not appeared:
                    settle_ends = now + _SETTLE_MAX_S
                appeared[(item[1], item[2])] = None
                due = min(now + _SETTLE_S, settle_ends)
                return
            if appeared:
                held.append(item)
                return
            _, key, payload, recv_ns, origin, _ = item
            if origin is not None:
                _, sensor = parse_sensor_topic(key)
                if seqs.gap(sensor, origin.source, origin.sn) is not None:
                    _fill(session, recorder, codec, seqs, [(key, origin.source)], origin.sn)
                if seqs.observe(sensor, origin.source, origin.sn).redelivered:
                    return
            _write(recorder, codec, key, payload, recv_ns)

        def fill_appeared() -> None:
            _fill(session, recorder, codec, seqs, list(appeared), None)
            appeared.clear()
            for item in held:
                take(item)
            held.clear()

        try:
            while not stop.is_set():
                try:
                    item = q.get(timeout=max(0.0, due - time.monotonic()) if appeared else 0.2)
                except queue.Empty:
                    item = None
                if item is not None:
                    take(item)
                if appeared and time.monotonic() >= due:
                    fill_appeared()
                if item is None:
                    recorder.maybe_flush()
        finally:
            token.undeclare()
            watch.undeclare()
            sub.undeclare()
            while not q.empty():
                take(q.get_nowait())
            if appeared:
                fill_appeared()
            recorder.close()
    return recorder.messages


def _fill(session: Any, recorder: McapRecorder, codec: zenoh_io.BlockCodec,
          seqs: SequenceTracker, publishers: list[tuple[str, str]], before_sn: int | None
          ) -> None:
    """Record what the ``publishers`` (key, source) still cache after the last message taken
    from each (and before ``before_sn``, if given), in sensor-time order across them (each
    publisher's own order kept)."""
    fetched = []
    for key, source in publishers:
        _, sensor = parse_sensor_topic(key)
        first = seqs.gap(sensor, source, None)[0]
        last = None if before_sn is None else before_sn - 1
        try:
            replies = zenoh_io.fetch_cached(session, key, source, (first, last),
                                            _FETCH_TIMEOUT_S)
        except zenoh_io.zenoh.ZError as exc:
            log.warning("could not ask a sensor publisher's cache",
                        extra={"fields": {"key": key, "error": repr(exc)}})
            continue
        fetched.extend((_first_time(codec, key, payload), key, payload)
                       for payload, origin in replies
                       if not seqs.observe(sensor, origin.source, origin.sn).redelivered)
    fetched.sort(key=lambda f: f[0])  # stable
    for _, key, payload in fetched:
        _write(recorder, codec, key, payload, time.time_ns())


def _first_time(codec: zenoh_io.BlockCodec, key: str, payload: bytes) -> int:
    """A sensor message's first sample time, the time a replay orders it by (0 if it does
    not decode: :func:`_write` logs it)."""
    try:
        return codec.decode(key, payload, 0).t_first_ns
    except ValueError:
        return 0


def _document_time(payload: bytes, recv_ns: int) -> int:
    """A status's or alert's sensor time (``now_ns`` / ``at_ns``), as the daemon's own
    recording stamps them; the receive time for any other document."""
    try:
        doc = json.loads(payload)
    except ValueError:
        return recv_ns
    t = doc.get("at_ns") or doc.get("now_ns") if isinstance(doc, dict) else None
    return t if isinstance(t, int) and not isinstance(t, bool) and t > 0 else recv_ns


def _write(recorder: McapRecorder, codec: zenoh_io.BlockCodec, key: str, payload: bytes,
           recv_ns: int) -> None:
    try:
        parse_sensor_topic(key)
    except ValueError:  # status, alerts, anything else: JSON documents
        if payload:  # an empty payload is a DELETE (a cleared alert): no document to keep
            recorder.write(key, payload, JSON_OBJECT, recv_ns, _document_time(payload, recv_ns))
        return
    try:
        block = codec.decode(key, payload, recv_ns)
    except ValueError as exc:
        log.warning("undecodable sensor message not recorded",
                    extra={"fields": {"key": key, "error": str(exc)}})
        return
    recorder.write(key, payload, codec.channel_spec(block.sensor), recv_ns, block.t_first_ns)


def run(args: argparse.Namespace) -> int:
    try:
        raw = read_toml(args.config)
        dcfg = parse_daemon_sections(raw)
        buoy = raw.get("buoy", {})
        buoy_id = validate_buoy_id(buoy.get("id", "") if isinstance(buoy, dict) else "")
    except (ValueError, OSError) as exc:  # the buoy id's error, an OSError: name the file
        log.error(str(exc) if isinstance(exc, ConfigError) else f"config error: {args.config}: {exc}")
        return 2
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda signum, frame: stop.set())
    recorder = McapRecorder(args.output, dcfg.record.rotate_s, dcfg.record.flush_interval_s)
    zc = client_side(dcfg.zenoh)
    try:
        n = record(buoy_id, zc, recorder, stop, zenoh_io.default_codec())
    except zenoh_io.zenoh.ZError as exc:  # the session did not open: nothing to record from
        recorder.close()
        log.error(f"cannot reach the daemon of buoy {buoy_id!r} at {list(zc.connect)} "
                  f"([zenoh] of {args.config}): is `buoymon run` running? ({exc})")
        return 1
    log.info("recording stopped", extra={"fields": {"messages": n, "files": recorder.files}})
    return 0
