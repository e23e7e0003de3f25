"""`buoymon replay --rrd OUT.rrd` stopped by a real signal (Ctrl-C's SIGINT, a service
manager's SIGTERM): the recording so far is kept as OUT.partial.rrd, named on stderr, and a
readable Rerun file; OUT.rrd is never a partial recording (an earlier one stays as it was);
the exit status is the shell's for the signal. A replay that ends well leaves OUT.rrd only.
Was: a partial OUT.rrd with no mark, and SIGTERM ended the replay without a word."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from viz_helpers import read_rrd
from waiting import wait_until

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}
HOURS = 0.25


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("interrupted") / "sim.mcap"
    subprocess.run([sys.executable, "-m", "monitor.cli", "simulate", "-o", str(path),
                    "--hours", str(HOURS), "--hs", "1", "--tp", "6", "--seed", "3"],
                   env=ENV, check=True, capture_output=True, timeout=300)
    return path


@pytest.fixture(scope="module")
def short_horizon(tmp_path_factory) -> Path:
    """The shipped configuration with a 10-s replay ordering horizon (default 1 h), so that a
    paced replay sends fatigue figures to the recording from its first seconds."""
    text = (REPO / "monitor" / "vaps_seed004.toml").read_text()
    assert "\nreplay_horizon_s = 3600.0 " in text
    path = tmp_path_factory.mktemp("interrupted_cfg") / "short.toml"
    path.write_text(text.replace("\nreplay_horizon_s = 3600.0 ", "\nreplay_horizon_s = 10.0 "))
    return path


def _replay(log: Path, rrd: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "monitor.cli", "replay", str(log),
                             "--no-progress", "--rrd", str(rrd), *extra],
                            env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("sig, status, said", [
    (signal.SIGINT, 130, "buoymon: interrupted"),
    (signal.SIGTERM, 143, "buoymon: stopped (SIGTERM)"),
])
def test_a_stopped_replay_keeps_its_recording_as_partial_and_says_so(log, short_horizon, tmp_path,
                                                                     sig, status, said):
    rrd = tmp_path / "out.rrd"
    rrd.write_bytes(b"an earlier recording")
    partial = tmp_path / "out.partial.rrd"
    # paced at 30x: the 15-min log takes 30 s, stopped once the recording has grown
    proc = _replay(log, rrd, "--speed", "30", "--config", str(short_horizon))
    try:
        wait_until(lambda: partial.exists() and partial.stat().st_size > 20_000, timeout=60,
                   what="the partial recording to grow")
        # the recording's first flush (fatigue figures included) done: it stopped growing
        # (the next comes 30 s later); a stop inside a flush loses what that flush held
        sizes = [0, partial.stat().st_size]
        while sizes[-1] != sizes[-2]:
            time.sleep(1.0)
            sizes.append(partial.stat().st_size)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == status, err
    assert (f"replay: the Rerun recording is partial, kept as {partial} (the replay did not "
            f"finish; {rrd} not written)") in err.splitlines(), err
    assert said in err.splitlines() and "Traceback" not in err
    assert rrd.read_bytes() == b"an earlier recording"
    assert "rerun recording:" not in out  # no report of a finished recording
    # the partial recording is a Rerun file that reads back, with the fatigue figures so far
    damage = np.array(read_rrd(partial)["damage/conductor/committed"]["Scalars:scalars"],
                      dtype=float)
    assert len(damage) >= 1 and np.all(np.isfinite(damage))


def test_a_replay_that_ends_well_leaves_the_whole_recording_only(log, tmp_path):
    rrd = tmp_path / "out.rrd"
    rrd.write_bytes(b"an earlier recording")
    proc = _replay(log, rrd)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert f"rerun recording: {rrd} (open it with `buoymon view {rrd}`)" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.rrd"]
    envelope = np.array(read_rrd(rrd)["tension/load"]["Scalars:scalars"], dtype=float)
    assert 0.95 * HOURS * 3600 <= len(envelope) <= HOURS * 3600 + 1
