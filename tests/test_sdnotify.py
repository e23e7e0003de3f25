"""sd_notify over a real unix datagram socket, as systemd provides it."""

import os
import socket

from monitor.sdnotify import SdNotifier


def _listen(path):
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(path)
    s.settimeout(2)
    return s


def test_ready_watchdog_stopping_reach_the_socket(tmp_path):
    path = str(tmp_path / "notify")
    server = _listen(path)
    n = SdNotifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "30000000"})
    assert n.enabled and n.watchdog_interval_s == 15.0
    assert n.ready("serving")
    assert server.recv(4096) == b"READY=1\nSTATUS=serving"
    assert n.watchdog() and server.recv(4096) == b"WATCHDOG=1"
    assert n.stopping() and server.recv(4096) == b"STOPPING=1"
    n.close()
    server.close()


def test_abstract_socket_address():
    name = f"buoymon-test-{os.getpid()}"
    server = _listen("\0" + name)
    n = SdNotifier({"NOTIFY_SOCKET": "@" + name})
    assert n.ready()
    assert server.recv(4096) == b"READY=1"
    n.close()
    server.close()


def test_without_systemd_everything_is_a_no_op():
    n = SdNotifier({})
    assert not n.enabled and n.watchdog_interval_s is None
    assert not n.ready() and not n.watchdog() and not n.stopping()


def test_watchdog_meant_for_another_pid_is_ignored(tmp_path):
    n = SdNotifier({"NOTIFY_SOCKET": str(tmp_path / "x"), "WATCHDOG_USEC": "1000000",
                    "WATCHDOG_PID": str(os.getpid() + 1)})
    assert n.watchdog_interval_s is None
    assert not n.ready()  # nobody listens on that path: reported, not raised
    n.close()


def test_a_reader_that_never_reads_cannot_stall_the_sender(tmp_path):
    path = str(tmp_path / "notify")
    server = _listen(path)
    n = SdNotifier({"NOTIFY_SOCKET": path})
    sent = [n.watchdog() for _ in range(2000)]  # far beyond the kernel's datagram queue
    assert sent[0] and not all(sent)
    n.close()
    server.close()
