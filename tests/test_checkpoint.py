"""Crash-safe checkpoint store: lossless state encoding, atomic replacement under kill -9."""

import math
import os
import random
import signal
import subprocess
import sys
import time
import zlib
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
from monitor.state_part import Part
store = CheckpointStore(sys.argv[1])
i = (store.load().state["i"] if store.load() else 0)
while True:
    i += 1
    # each save: one write-once part in, one out (as a closed minute of late copies)
    store.save({"i": i, "payload": np.full(20000, float(i)),
                "parts": [Part(f"{j}," * 3000) for j in range(i, i + 3)]})
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
        # all of one save or none of it: the payload and the parts (those of this state and
        # no other in the file) match the counter it was saved with
        assert np.all(cp.state["payload"] == float(cp.state["i"]))
        i = cp.state["i"]
        assert cp.state["parts"] == [f"{j}," * 3000 for j in range(i, i + 3)]
        assert len(_parts(path)) == 3
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
        f"buoymon status: no daemon answered at tcp/127.0.0.1:{port} ([zenoh] listen/connect) "
        f"within 0.5 s, and "
        f"{path}: the checkpoint is empty (the daemon never saved)\n")
    path.unlink()
    assert main(["status", "--config", str(cfg), "--timeout", "0.5"]) == 1
    assert capsys.readouterr().err.endswith(
        f"within 0.5 s, and there is no state file at {path} ([state] path)\n")


def _parts(path) -> dict[str, bytes]:
    import sqlite3  # noqa: PLC0415

    db = sqlite3.connect(path)
    try:
        return dict(db.execute("SELECT key, data FROM parts"))
    finally:
        db.close()


def test_write_once_parts_are_written_with_the_first_checkpoint_holding_them_only(tmp_path):
    """The late copies' closed minutes (monitor.state_part.Part) were rewritten with the whole
    state every checkpoint: now a part is one row under its hash, inserted by the first save
    that holds it, deleted by the first that does not; the state row refers to it."""
    from monitor.state_part import Part, part_key  # noqa: PLC0415

    path = tmp_path / "state.sqlite"
    a, b, c = (Part(x * 5000) for x in "abc")
    store = CheckpointStore(path)
    db = store._db  # the store's own connection: total_changes counts the rows it wrote

    def rows_written(state) -> int:
        before = db.total_changes
        store.save(state)
        return db.total_changes - before

    assert rows_written({"m": [a, b, "open 1"]}) == 3  # two parts and the state row
    assert rows_written({"m": [a, b, "open 2"]}) == 1  # the state row only
    assert rows_written({"m": [b, c, "open 3"]}) == 3  # c in, a out, the state row
    assert _parts(path) == {part_key(b"b" * 5000): b"b" * 5000, part_key(b"c" * 5000): b"c" * 5000}
    blob = zlib.decompress(db.execute("SELECT state FROM checkpoint").fetchone()[0])
    assert blob.count(b'"__t":"part"') == 2 and b"bbbb" not in blob  # references, not parts
    store.close()
    again = CheckpointStore(path)
    back = again.load().state
    assert back == {"m": ["b" * 5000, "c" * 5000, "open 3"]}
    assert [type(x) for x in back["m"]] == [Part, Part, str]  # saved again as references
    assert again._db.total_changes == 0
    again.save(back)
    assert again._db.total_changes == 1
    again.close()
    # without a store (a replay's state file, the state queryable) a part is its string
    assert decode_state(encode_state({"m": [b]})) == {"m": ["b" * 5000]}
    assert b"bbbb" in encode_state({"m": [b]})


def test_a_missing_or_damaged_part_is_restored_as_none_and_replaced_by_the_next_save(tmp_path):
    """A part row gone or not matching its hash (a damaged card) costs that part only: it
    comes back as None (the late copies then say which minutes they lost), the rest loads,
    and the next save deletes the damaged row or writes it again if the state holds it."""
    import sqlite3  # noqa: PLC0415

    from monitor.state_part import Part, part_key  # noqa: PLC0415

    path = tmp_path / "state.sqlite"
    parts = [Part(f"minute {i} " * 300) for i in range(4)]
    store = CheckpointStore(path)
    store.save({"t": parts, "damage": 0.5})
    store.close()
    db = sqlite3.connect(path)
    db.execute("DELETE FROM parts WHERE key = ?", (parts[0].key,))
    db.execute("UPDATE parts SET data = substr(data, 1, 100) WHERE key = ?", (parts[1].key,))
    db.execute("UPDATE parts SET data = 'x' || substr(data, 2) WHERE key = ?", (parts[2].key,))
    db.commit()
    db.close()
    store = CheckpointStore(path)
    assert store.load().state == {"t": [None, None, None, parts[3]], "damage": 0.5}
    store.save({"t": [parts[2], parts[3]], "damage": 0.6})  # 2 held again (re-made), 1 not
    store.close()
    assert _parts(path) == {p.key: p.encode() for p in parts[2:]}
    assert part_key(parts[2].encode()) == parts[2].key
    store = CheckpointStore(path)
    assert store.load().state == {"t": parts[2:], "damage": 0.6}
    store.close()


_STEP_KILLER = """
import os, sys
from monitor.checkpoint import CheckpointStore
from monitor.state_part import Part

path, step = sys.argv[1], int(sys.argv[2])
store = CheckpointStore(path)
old = store.load()
if old is None:
    store.save({"n": 1, "t": [Part("a" * 9000), Part("b" * 9000), "open 1"]})
    sys.exit(0)


class Dying:
    # the store's connection, dying (as a kill -9 would) before its step-th statement
    def __init__(self, db):
        self.db, self.calls = db, 0

    def execute(self, *a):
        return self.step("execute", *a)

    def executemany(self, *a):
        return self.step("executemany", *a)

    def step(self, name, *a):
        self.calls += 1
        if self.calls == step:
            os._exit(9)
        return getattr(self.db, name)(*a)


store._db = Dying(store._db)
store.save({"n": 2, "t": [Part("b" * 9000), Part("c" * 9000), "open 2"]})
sys.exit(0 if step > store._db.calls else 3)
"""


@pytest.mark.integration  # kills writer processes
def test_a_process_killed_at_any_step_of_a_save_leaves_one_whole_checkpoint(tmp_path):
    """Parts and the state referring to them go in one transaction: a writer killed before
    each statement of a save (BEGIN, part inserts, part deletes, the sequence read, the state
    row, COMMIT) leaves the previous checkpoint with all its parts, or the new one."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    seen = []
    for step in range(1, 8):
        path = tmp_path / f"state{step}.sqlite"
        for _ in range(2):  # the first checkpoint, then the save killed at ``step``
            p = subprocess.run([sys.executable, "-c", _STEP_KILLER, str(path), str(step)],
                               env=env, capture_output=True, text=True)
        store = CheckpointStore(path)
        state = store.load().state
        store.close()
        seen.append((p.returncode, state["n"]))
        want = {1: ["a" * 9000, "b" * 9000, "open 1"], 2: ["b" * 9000, "c" * 9000, "open 2"]}
        assert state["t"] == want[state["n"]]
        assert sorted(_parts(path).values()) == sorted(x.encode() for x in want[state["n"]][:2])
    # killed before each of the six statements: the old checkpoint; not killed: the new one
    assert seen == [(9, 1)] * 6 + [(0, 2)]


def test_the_state_row_is_deflated_and_a_plain_json_row_of_before_still_loads(tmp_path):
    """The row is deflated (the daemon's 1.4 MB state was written whole every 10 s): a
    checkpoint written before, plain JSON, loads as it did."""
    import sqlite3  # noqa: PLC0415

    state = {"ring": np.arange(20000, dtype=np.int64) * 50_000_000, "damage": 0.25}
    store = CheckpointStore(tmp_path / "new.sqlite")
    store.save(state)
    row = store._db.execute("SELECT state FROM checkpoint").fetchone()[0]
    store.close()
    # base64 alone is 4/3 of the bytes: deflated, 0.5 of the JSON here
    assert len(row) < 0.6 * len(encode_state(state))
    old = tmp_path / "old.sqlite"
    CheckpointStore(old).close()
    db = sqlite3.connect(old)
    db.execute("INSERT INTO checkpoint VALUES (1, 7, 1, ?)", (encode_state(state),))
    db.commit()
    db.close()
    for path in (tmp_path / "new.sqlite", old):
        store = CheckpointStore(path)
        back = store.load().state
        store.close()
        assert np.array_equal(back["ring"], state["ring"]) and back["damage"] == 0.25
