"""Crash-safe checkpoint store: lossless state encoding, atomic replacement under kill -9."""

import math
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from monitor.checkpoint import CheckpointStore, PeriodicCheckpointer, decode_state, encode_state

REPO = Path(__file__).resolve().parents[1]


def test_state_round_trips_bit_for_bit():
    state = {
        "residue": np.array([1.5, -2.25, np.nan, np.inf, 5e-324]),
        "hist": np.arange(12, dtype=np.int64).reshape(3, 4),
        "f32": np.float32(0.1),
        "damage": 0.1 + 0.2,
        "neg_inf": -math.inf,
        "pair": (1, "a"),
        "blob": b"\x00\xff",
        "nested": [{"ok": True, "none": None}],
    }
    back = decode_state(encode_state(state))
    assert back["residue"].tobytes() == state["residue"].tobytes()
    assert back["hist"].dtype == np.int64 and back["hist"].shape == (3, 4)
    assert np.array_equal(back["hist"], state["hist"])
    assert back["f32"].dtype == np.float32 and back["f32"] == np.float32(0.1)
    assert back["damage"] == 0.30000000000000004
    assert back["neg_inf"] == -math.inf
    assert back["pair"] == (1, "a") and back["blob"] == b"\x00\xff"
    assert back["nested"] == [{"ok": True, "none": None}]


@pytest.mark.parametrize("bad, what", [
    ({1: 2}, "state keys must be strings"),
    ({"x": object()}, "cannot store a value of type object"),
    ({"x": np.array([object()])}, "object arrays cannot be stored"),
])
def test_unstorable_state_is_a_clear_error(bad, what):
    with pytest.raises(ValueError, match=what):
        encode_state(bad)


def test_store_keeps_only_the_latest_and_counts(tmp_path):
    store = CheckpointStore(tmp_path / "sub" / "state.sqlite")
    assert store.load() is None
    assert store.save({"a": 1}) == 1
    assert store.save({"a": 2}) == 2
    store.close()
    again = CheckpointStore(tmp_path / "sub" / "state.sqlite")
    cp = again.load()
    assert (cp.seq, cp.state) == (2, {"a": 2})
    mode = again._db.execute("PRAGMA journal_mode").fetchone()[0]
    sync = again._db.execute("PRAGMA synchronous").fetchone()[0]
    assert (mode, sync) == ("wal", 2)  # 2 = FULL
    again.close()


@pytest.mark.integration  # starts the daemon process
def test_a_file_that_is_not_a_checkpoint_is_refused_and_left_alone(tmp_path):
    bad = tmp_path / "state.sqlite"
    bad.write_bytes(b"garbage, not SQLite" * 10)
    with pytest.raises(ValueError, match=f"{bad}: not a checkpoint database .*move it aside"):
        CheckpointStore(bad)
    assert bad.read_bytes() == b"garbage, not SQLite" * 10
    # the daemon (a real process): a clear error and exit status 2, no traceback
    cfg = tmp_path / "cfg.toml"
    cfg.write_text((Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml")
                   .read_text() + f'\n[state]\npath = "{bad}"\n[metrics]\nenabled = false\n')
    p = subprocess.run([sys.executable, "-m", "monitor.cli", "run", "--config", str(cfg)],
                       capture_output=True, text=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": str(REPO)})
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "not a checkpoint database (file is not a database)" in p.stderr
    assert bad.read_bytes() == b"garbage, not SQLite" * 10


@pytest.mark.integration  # starts the daemon and status processes
def test_a_damaged_checkpoint_is_named_and_left_alone(tmp_path):
    """A checkpoint database whose state blob is damaged: the daemon and `buoymon status` said
    only "Expecting value: line 1 column 1 (char 0)"."""
    path = tmp_path / "state.sqlite"
    store = CheckpointStore(path)
    assert store.save({"a": 1}) == 1
    store._db.execute("UPDATE checkpoint SET state = x'00112233' WHERE id = 1")
    store.close()
    data = path.read_bytes()
    with pytest.raises(ValueError, match=f"{path}: checkpoint 1 is damaged .*move it aside"):
        CheckpointStore(path).load()
    cfg = tmp_path / "cfg.toml"
    cfg.write_text((Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml")
                   .read_text() + f'\n[state]\npath = "{path}"\n[metrics]\nenabled = false\n'
                   '[zenoh]\nlisten = ["tcp/127.0.0.1:1"]\n')  # nothing answers a status query
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    for cmd, rc in ((["run"], 2), (["status"], 1)):
        p = subprocess.run([sys.executable, "-m", "monitor.cli", *cmd, "--config", str(cfg)],
                           capture_output=True, text=True, timeout=120, env=env)
        assert p.returncode == rc and "Traceback" not in p.stderr, p.stderr
        assert f"{path}: checkpoint 1 is damaged (" in p.stderr, p.stderr
    assert path.read_bytes() == data


def test_periodic_checkpointer_respects_interval():
    now = [100.0]
    saved = []

    class Store:
        def save(self, s):
            saved.append(s)
            return len(saved)

    cp = PeriodicCheckpointer(Store(), lambda: {"t": now[0]}, 5.0, clock=lambda: now[0])
    assert not cp.maybe_save() and cp.due_in() == 5.0
    now[0] = 104.9
    assert not cp.maybe_save()
    now[0] = 105.0
    assert cp.maybe_save() and saved == [{"t": 105.0}]
    assert cp.due_in() == 5.0
    cp.save_now()
    assert cp.saves == 2


_WRITER = """
import sys, numpy as np
from monitor.checkpoint import CheckpointStore
store = CheckpointStore(sys.argv[1])
i = (store.load().state["i"] if store.load() else 0)
while True:
    i += 1
    store.save({"i": i, "payload": np.full(20000, float(i))})
    print(i, flush=True)
"""


@pytest.mark.integration  # kills writer processes
def test_kill_9_during_saves_leaves_a_whole_checkpoint(tmp_path):
    path = tmp_path / "state.sqlite"
    rng = random.Random(6)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    last_acked = 0
    for _ in range(8):
        proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], env=env,
                                stdout=subprocess.PIPE, text=True)
        first = int(proc.stdout.readline())  # at least one save made it in this life
        assert first == last_acked + 1  # resumed from the checkpoint, nothing skipped
        time.sleep(rng.uniform(0.0, 0.15))
        proc.send_signal(signal.SIGKILL)
        out = proc.communicate()[0].split()
        acked = int(out[-1]) if out else first
        store = CheckpointStore(path)
        cp = store.load()
        store.close()
        # all of one save or none of it: the payload matches the counter it was saved with
        assert np.all(cp.state["payload"] == float(cp.state["i"]))
        # every save acknowledged (printed after commit) is durable; at most one more landed
        assert acked <= cp.state["i"] <= acked + 1
        last_acked = cp.state["i"]
    assert last_acked > 8


def test_status_without_an_answer_says_so_before_the_state_file(tmp_path, capsys):
    """A daemon that does not answer (stopped, or busy at its start) with a checkpoint not yet
    written: `buoymon status` said only "PATH: the checkpoint is empty (the daemon never
    saved)", as if no daemon were configured."""
    from daemon_harness import free_port  # noqa: PLC0415
    from monitor.cli import main  # noqa: PLC0415

    path = tmp_path / "state.sqlite"
    CheckpointStore(path).close()  # created, nothing saved yet
    port = free_port()
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(f'[buoy]\nid = "b1"\n[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
                   f'[state]\npath = "{path}"\n')
    assert main(["status", "--config", str(cfg), "--timeout", "0.5"]) == 1
    assert capsys.readouterr().err == (
        f"buoymon status: no daemon answered at tcp/127.0.0.1:{port} within 0.5 s, and "
        f"{path}: the checkpoint is empty (the daemon never saved)\n")
    path.unlink()
    assert main(["status", "--config", str(cfg), "--timeout", "0.5"]) == 1
    assert capsys.readouterr().err.endswith(
        f"within 0.5 s, and there is no state file at {path} ([state] path)\n")
