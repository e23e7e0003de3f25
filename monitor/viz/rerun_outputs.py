"""Where Rerun data goes: an ``.rrd`` file, a running viewer (gRPC), or a web viewer we serve.

Two safety rules for everything started here:

* Network: the Python SDK's ``rr.serve_grpc``/``rr.serve_web_viewer`` bind all interfaces with
  no option to change it, so a served viewer is the ``rerun`` CLI run as a subprocess with
  ``--serve-web --bind 127.0.0.1`` (both its gRPC proxy and its web server then listen on
  loopback only), and the SDK streams to it as a gRPC client.
* Analytics: rerun 0.41 has no environment switch to disable its usage analytics (only
  ``FORCE_RERUN_ANALYTICS`` to force them on); the opt-out is a config file written by
  ``rerun analytics disable`` under ``$XDG_CONFIG_HOME/rerun/``. Every ``rerun`` process we
  start therefore runs with ``XDG_CONFIG_HOME``/``XDG_DATA_HOME`` pointing at a private
  directory in which ``rerun analytics disable`` has been run first (on a first run nothing is
  sent before that). The SDK's file and gRPC-client sinks send no analytics.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import rerun as rr

from monitor.viz.port_owner import port_listeners
from monitor.viz.rerun_options import RerunOptions

if TYPE_CHECKING:
    from monitor.viz.rerun_sink import RerunSink, ShapeProvider

APPLICATION_ID = "buoymon"


def rerun_command() -> list[str]:
    """The rerun CLI shipped in the rerun-sdk wheel, run by this interpreter."""
    return [sys.executable, "-m", "rerun_cli"]


def analytics_disabled_env(config_home: Path | None = None) -> dict[str, str]:
    """Environment for a ``rerun`` subprocess with analytics disabled (see module docstring).

    ``config_home`` defaults to ``<tmp>/buoymon-rerun-<uid>``; the opt-out is written once.
    """
    home = Path(config_home or Path(tempfile.gettempdir()) / f"buoymon-rerun-{os.getuid()}")
    home.mkdir(parents=True, exist_ok=True, mode=0o700)
    if home.stat().st_uid != os.getuid():  # a shared /tmp: never use someone else's config
        raise RuntimeError(f"rerun config directory {home} is not owned by this user")
    env = dict(os.environ, XDG_CONFIG_HOME=str(home), XDG_DATA_HOME=str(home))
    env.pop("FORCE_RERUN_ANALYTICS", None)
    if not analytics_disabled(home):
        subprocess.run(rerun_command() + ["analytics", "disable"], env=env, check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)
        if not analytics_disabled(home):
            raise RuntimeError(f"could not disable rerun analytics in {home}")
    return env


def analytics_disabled(config_home: Path) -> bool:
    """True if the rerun analytics config under ``config_home`` says disabled."""
    path = Path(config_home) / "rerun" / "analytics.json"
    try:
        return json.loads(path.read_text()).get("analytics_enabled") is False
    except (OSError, ValueError):
        return False


@dataclass
class WebViewer:
    """A ``rerun --serve-web`` subprocess on 127.0.0.1; :meth:`stop` ends it."""

    process: subprocess.Popen
    web_url: str
    grpc_url: str

    def stop(self, timeout_s: float = 10.0) -> None:
        """End the viewer and the server it forks (both are in the viewer's process group)."""
        try:
            os.killpg(self.process.pid, signal.SIGTERM)
            self.process.wait(timeout_s)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            pass
        try:  # the forked server can outlive its parent: end whatever is left of the group
            os.killpg(self.process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.process.wait()


def _wait_listening(port: int, proc: subprocess.Popen, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"rerun web viewer exited with status {proc.returncode}")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise RuntimeError(f"rerun web viewer did not listen on 127.0.0.1:{port} within {timeout_s} s")


def check_ports_free(ports: dict[str, int]) -> None:
    """RuntimeError naming the process that holds a port a viewer needs ({what: port}):
    started anyway, the new viewer could not bind, and the URL would show the old viewer's
    recording."""
    for what, port in ports.items():
        holders = port_listeners(port)
        if holders:
            raise RuntimeError(
                f"{what} port {port} is already in use by {', '.join(map(str, holders))}; "
                "stop it (an earlier `buoymon view`?) or choose other ports "
                "(--web-port, --grpc-port)")


def _check_ours(options: RerunOptions, proc: subprocess.Popen) -> None:
    """RuntimeError unless every listener on the viewer's ports is in its process group."""
    for port in (options.web_port, options.grpc_port):
        for holder in port_listeners(port):
            try:
                ours = holder.pid and os.getpgid(holder.pid) == proc.pid
            except ProcessLookupError:
                ours = False
            if not ours:
                raise RuntimeError(f"port {port} was taken by {holder} while the viewer "
                                   "started")


def serve_web_viewer(options: RerunOptions, config_home: Path | None = None,
                     timeout_s: float = 30.0, recordings: tuple[Path, ...] = ()) -> WebViewer:
    """Start a web viewer bound to 127.0.0.1 with a capped buffer (oldest data dropped),
    serving live data sent to its gRPC proxy or the given ``.rrd`` files. RuntimeError when
    a port is held by another process (named in the message)."""
    check_ports_free({"web": options.web_port, "gRPC": options.grpc_port})
    cmd = rerun_command() + [
        "--serve-web", "--bind", "127.0.0.1",
        "--port", str(options.grpc_port), "--web-viewer-port", str(options.web_port),
        "--server-memory-limit", options.server_memory_limit,
        *[str(p) for p in recordings],
    ]
    # own process group: `rerun` forks its server, and stop() must end both
    proc = subprocess.Popen(cmd, env=analytics_disabled_env(config_home),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        _wait_listening(options.grpc_port, proc, timeout_s)
        _wait_listening(options.web_port, proc, timeout_s)
        _check_ours(options, proc)
    except BaseException:  # also a signal turned exception (buoymon view): never leak it
        WebViewer(proc, "", "").stop()
        raise
    grpc = f"rerun+http://127.0.0.1:{options.grpc_port}/proxy"
    return WebViewer(proc, f"http://127.0.0.1:{options.web_port}/?url={grpc}", grpc)


def open_recording(buoy_id: str, options: RerunOptions, *, rrd: str | Path | None = None,
                   viewer: WebViewer | None = None) -> rr.RecordingStream:
    """A recording stream for one buoy with every output the options ask for.

    ``rrd`` overrides ``options.rrd``; ``viewer`` (from :func:`serve_web_viewer`) adds its gRPC
    proxy; ``options.connect`` adds a running viewer. Raises ValueError if there is no output.
    """
    sinks: list[rr.FileSink | rr.GrpcSink] = []
    path = rrd or options.rrd
    if path:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        sinks.append(rr.FileSink(str(path)))
    if options.connect:
        sinks.append(rr.GrpcSink(options.connect))
    if viewer is not None:
        sinks.append(rr.GrpcSink(viewer.grpc_url))
    if not sinks:
        raise ValueError("rerun output: set rerun.rrd, rerun.connect or rerun.serve_web")
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=buoy_id)
    rec.set_sinks(*sinks)
    return rec


def open_rerun_sink(buoy_id: str, options: RerunOptions, *, rrd: str | Path | None = None,
                    shape_provider: "ShapeProvider | None" = None, replay: bool = False,
                    config_home: Path | None = None) -> tuple["RerunSink", WebViewer | None]:
    """The sink the replay (``--rrd``, ``replay=True`` for the bulk preset) and the daemon
    (``[rerun]`` section: ``rrd``, ``connect``, ``serve_web``) use. The caller stops the
    returned web viewer, if any, after closing the sink."""
    from monitor.viz.rerun_sink import RerunSink

    opts = options.for_replay() if replay else options
    viewer = serve_web_viewer(opts, config_home) if opts.serve_web else None
    try:
        rec = open_recording(buoy_id, opts, rrd=rrd, viewer=viewer)
    except ValueError:
        if viewer is not None:
            viewer.stop()
        raise
    return RerunSink(rec, opts, shape_provider=shape_provider), viewer
