"""Which process listens on a local TCP port (Linux /proc), to name it when a port is taken.

A viewer left over from an earlier ``buoymon view`` keeps its ports; a new viewer then fails to
bind, and a browser opening the port would show the old recording. Naming the listener lets
the user stop the right process.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

_LISTEN = "0A"  # TCP state LISTEN in /proc/net/tcp*


@dataclass(frozen=True)
class Listener:
    """A process listening on a port: its pid and command line; pid 0 when the socket's
    owner is not visible (another user's process)."""

    pid: int
    command: str

    def __str__(self) -> str:
        if not self.pid:
            return "a process of another user"
        return f"pid {self.pid} ({self.command})"


def _listening_inodes(port: int) -> set[str]:
    inodes = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            cols = line.split()
            if cols[3] == _LISTEN and int(cols[1].rsplit(":", 1)[1], 16) == port:
                inodes.add(cols[9])
    return inodes


def _command(pid: int) -> str:
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return "?"
    return " ".join(a.decode(errors="replace") for a in raw.split(b"\0") if a)


def port_listeners(port: int) -> list[Listener]:
    """The processes listening on ``port`` (any address); [] when the port is free."""
    inodes = _listening_inodes(port)
    if not inodes:
        return []
    wanted = {f"socket:[{i}]" for i in inodes}
    found: dict[int, Listener] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fds = list((entry / "fd").iterdir())
        except OSError:  # gone, or not ours to read
            continue
        for fd in fds:
            try:
                if os.readlink(fd) in wanted:
                    pid = int(entry.name)
                    found[pid] = Listener(pid, _command(pid))
                    break
            except OSError:
                continue
    return sorted(found.values(), key=lambda x: x.pid) or [Listener(0, "")]
