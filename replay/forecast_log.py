"""Sea-state forecasts recorded in MCAP logs (``buoy/<id>/forecast/waves``, JSON), for a
replay to hand to the pipeline as the daemon did: each with the publish time the daemon
recorded, its due time (:mod:`monitor.forecast`).

The sample reader (:mod:`replay.reader`) reads sensor blocks only; forecasts are few, so
they are read here with the ``mcap`` package in one pass over the messages of their topic.
"""

from __future__ import annotations

import json
import logging
import re
import struct
from pathlib import Path
from typing import Any, Sequence

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader

log = logging.getLogger(__name__)


FORECAST_TOPIC = re.compile(r"buoy/([^/]+)/forecast/waves")


def read_forecasts(files: Sequence[str | Path]) -> list[tuple[str, Any, int]]:
    """Recorded forecasts as (buoy id, decoded JSON, due time ns), in due-time order. A file
    or message that cannot be read is logged and skipped (the sample reader reports damaged
    files)."""
    out: list[tuple[str, Any, int]] = []
    for path in files:
        before = len(out)
        try:
            with open(path, "rb") as fh:
                try:
                    summary = make_reader(fh).get_summary()
                except (McapError, ValueError, EOFError, struct.error):
                    summary = None  # no footer, or a damaged one: a recording cut short
                fh.seek(0)
                if summary is None:  # read on from the start as far as the file is whole
                    messages = NonSeekingReader(fh).iter_messages(log_time_order=False)
                else:  # only the forecast channels' chunks are read
                    topics = [c.topic for c in summary.channels.values()
                              if FORECAST_TOPIC.fullmatch(c.topic)]
                    if not topics:
                        continue
                    messages = make_reader(fh).iter_messages(topics=topics)
                for _, channel, msg in messages:
                    m = FORECAST_TOPIC.fullmatch(channel.topic)
                    if m is None:
                        continue
                    try:
                        out.append((m.group(1), json.loads(msg.data), int(msg.publish_time)))
                    except (ValueError, RecursionError) as exc:
                        log.warning("%s: unreadable forecast message: %s", path, exc)
        except (OSError, McapError, ValueError, EOFError, struct.error) as exc:
            # a recording cut by a power loss ends mid-record: what came before is kept
            log.warning("%s: damaged or not MCAP (%s): forecasts past the damage not read, "
                        "%d read before it", path, str(exc) or type(exc).__name__,
                        len(out) - before)  # mcap's EndOfFile has no message
    return sorted(out, key=lambda x: x[2])
