"""kill -9 at random moments, restart, re-deliver: the final damage equals an uninterrupted run.

The publisher re-delivers the whole stream after each restart (as a sensor buffer would from
a bit before the outage); samples at or before the checkpoint are skipped by the pipeline.
This test uses the fake pipeline of daemon_harness to check the daemon's checkpoint and
restart mechanics; test_daemon_e2e does the same with the real pipeline.
"""

import random
import subprocess
import sys

from monitor.checkpoint import CheckpointStore

from daemon_harness import (
    ENV, DaemonProcess, expected_total, free_port, tension_blocks, wait_until_state,
    write_config,
)
from test_daemon import HARNESS

N_BLOCKS = 120
SPEED = 100.0  # the whole stream takes 1.2 s


def test_twenty_kill_9_then_restart_equal_one_uninterrupted_run(tmp_path):
    port = free_port()
    state = tmp_path / "state.sqlite"
    cfg = write_config(tmp_path / "cfg.toml", port, state, checkpoint_s=0.1)
    endpoint = f"tcp/127.0.0.1:{port}"
    blocks = tension_blocks(N_BLOCKS)
    rng = random.Random(2026)
    progress = []
    for _ in range(20):
        d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
        d.wait_for("READY=1")
        pub = subprocess.Popen([sys.executable, HARNESS, "publish", endpoint, str(N_BLOCKS),
                                str(SPEED)], env=ENV, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
        try:
            pub.wait(timeout=rng.uniform(0.4, 2.2))
        except subprocess.TimeoutExpired:
            pass
        d.kill9()
        pub.kill()
        pub.wait()
        store = CheckpointStore(state)
        cp = store.load()
        store.close()
        progress.append(cp.state["pipeline"]["last_t"].get("tension", 0) if cp else 0)
    assert progress == sorted(progress)  # a checkpoint never goes back in time
    # kills did interrupt the stream part way, several times
    assert len({p for p in progress if 0 < p < blocks[-1].t_last_ns}) >= 3, progress
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    subprocess.run([sys.executable, HARNESS, "publish", endpoint, str(N_BLOCKS), "0"],
                   env=ENV, check=True, capture_output=True, timeout=60)
    wait_until_state(port, lambda s: s["state"]["pipeline"]["last_t"].get("tension")
                     == blocks[-1].t_last_ns)
    assert d.terminate() == 0
    store = CheckpointStore(state)
    cp = store.load()
    store.close()
    assert cp.state["pipeline"]["total"] == expected_total(blocks)  # to the last bit
    assert cp.state["pipeline"]["accepted"]["tension"] == N_BLOCKS * 20
