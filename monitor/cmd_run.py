"""``buoymon run --config CFG.toml``: the live monitoring daemon (see :mod:`monitor.daemon`)."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from typing import Any

from monitor.daemon import Daemon

log = logging.getLogger("buoymon.run")


def register(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = sub.add_parser("run",
                       description="Subscribe to buoy/<id>/sensor/**, run the pipeline core, "
                       "publish buoy/<id>/monitor/status, checkpoint state crash-safely.")
    p.add_argument("--config", required=True, metavar="CFG.toml", help="configuration file")
    p.set_defaults(func=run)


def build_daemon(path: str) -> Daemon:
    """Load and validate the whole configuration, then build (not start) the daemon."""
    from monitor.bridge.watch import BridgeWatch  # noqa: PLC0415
    from monitor.config import load_config  # noqa: PLC0415 (heavy: models, numba)
    from monitor.pipeline import Pipeline  # noqa: PLC0415
    from monitor.zenoh_io import default_codec  # noqa: PLC0415

    cfg = load_config(path)
    bridge_cfg = cfg.bridge  # [[source]]: the bridge runs inside the daemon (bridge.embedded)

    visual: list[Any] = []

    def make_pipeline(state: Any, sinks: Any) -> Pipeline:
        visual.extend(rerun_sinks(cfg))
        return Pipeline(cfg, [*sinks, *visual], state)

    def attach(session: Any, pipeline: Pipeline) -> list[Any]:
        out: list[Any] = [ClosingSinks(visual)]  # flushed and closed when the daemon stops
        out.append(BridgeWatch(session, cfg.buoy.id))  # bridges' status, in-process or not
        if bridge_cfg is not None:  # pynmea2, pyserial: imported only with sources
            from monitor.bridge.embedded import EmbeddedBridge  # noqa: PLC0415

            out.append(EmbeddedBridge(session, bridge_cfg))
        if hasattr(pipeline.alerts, "apply_command"):  # an alert rules engine is installed
            out.append(AlertDelivery(session, pipeline, cfg.alerts))
        return out

    if cfg.alerts.webhook or cfg.alerts.email or cfg.alerts.alertmanager:
        from monitor.alerts.outbox import Outbox  # noqa: PLC0415

        # opened here too, so a damaged outbox stops the start with its name (exit status 2),
        # not with a traceback once the daemon has begun to serve
        Outbox(cfg.alerts.outbox.path, {}).close()
    return Daemon(cfg.buoy.id, cfg.daemon, make_pipeline, default_codec(), attach=attach,
                  max_ahead_s=cfg.ordering.max_ahead_s)


def rerun_sinks(cfg: Any) -> list[Any]:
    """The live Rerun sink when ``[rerun]`` asks for an output (rrd, connect, serve_web); none
    otherwise. A viewer that cannot be reached costs the dashboard, never the monitoring."""
    if not (cfg.rerun.rrd or cfg.rerun.connect or cfg.rerun.serve_web):
        return []  # not configured: rerun is not even imported
    from monitor.viz.pipeline_sinks import open_rerun  # noqa: PLC0415

    try:
        return [open_rerun(cfg)]
    except (ValueError, RuntimeError, OSError) as exc:
        log.error("rerun output not started: %s", exc)
        return []


class ClosingSinks:
    """Daemon extension closing sinks (the Rerun output) at shutdown."""

    def __init__(self, sinks: list[Any]) -> None:
        self.sinks = sinks

    def poll(self) -> None:
        """Nothing to do between blocks."""

    def close(self) -> None:
        for sink in self.sinks:
            try:
                sink.close()
            except Exception as exc:  # noqa: BLE001 (a viewer gone away must not stop shutdown)
                log.error("closing %s: %s", type(sink).__name__, exc)


class AlertDelivery:
    """Alert transitions to Zenoh (and webhook/e-mail via the outbox); operator commands
    (``buoymon alerts ack|reset``) applied on the daemon's thread between blocks."""

    def __init__(self, session: Any, pipeline: Any, alerts: Any) -> None:
        from monitor.alerts.delivery import OutboxSink, ZenohAlertSink  # noqa: PLC0415

        self.engine = pipeline.alerts
        self.zenoh = ZenohAlertSink(session, pipeline.buoy_id, active=self.engine.active())
        self.outbox = OutboxSink.from_config(alerts, active=self.engine.active())
        # the daemon hands these the pipeline's alert transitions (monitor.daemon.Attach)
        self.alert_channels = [s for s in (self.zenoh, self.outbox) if s is not None]

    def poll(self) -> None:
        self.zenoh.apply_commands(self.engine)
        if self.outbox is not None:
            self.outbox.refresh()

    def status_fields(self) -> dict[str, Any]:
        """Per delivery channel: pending, dead letters, counters (monitor.daemon.Extension)."""
        if self.outbox is None:
            return {}
        return {"delivery": {"channels": self.outbox.outbox.stats()}}

    def close(self) -> None:
        self.zenoh.close()
        if self.outbox is not None:
            self.outbox.close()


def keep_scipy_out() -> None:
    """Make ``import scipy`` fail in this process: called first thing by ``buoymon run``.

    Nothing on the daemon's path uses scipy (tests/test_daemon_imports.py holds it to that),
    but numba imports it whenever it is installed: ``scipy`` for a version check and, when
    its compiler context starts, all of ``scipy.linalg`` to offer BLAS to ``np.dot`` in
    compiled code, which no kernel here calls: 14 MB of the daemon's resident memory
    (bench/bench_daemon.py) for nothing. numba takes the ImportError as "no scipy"; the
    cached kernels load the same machine code either way. A process that already has scipy
    is left alone.
    """
    sys.modules.setdefault("scipy", None)  # None in sys.modules: import raises ImportError


def run(args: argparse.Namespace) -> int:
    keep_scipy_out()
    try:
        daemon = build_daemon(args.config)
    except (ValueError, OSError) as exc:
        log.error(str(exc))
        return 2
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda signum, frame: daemon.stop())
    from monitor.zenoh_io import zenoh  # noqa: PLC0415 (loaded by the daemon anyway)

    try:
        daemon.run()
    except zenoh.ZError as exc:  # the session did not open: a port in use, a bad endpoint
        zc = daemon.config.zenoh
        log.error(f"[zenoh] cannot open the session (listen {list(zc.listen)}, connect "
                  f"{list(zc.connect)}): {exc}")
        return 2
    return 0
