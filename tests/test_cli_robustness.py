"""The command line under bad input and unusual use: a clear message and a non-zero status,
never a traceback, a silent wrong number or a destroyed input file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from replay.writer import LogWriter, Series

T0 = 946_684_800 * 10**9  # 2000-01-01T00:00:00Z


def tiny_log(path: Path, buoy: str = "qa", n: int = 40, t0_ns: int = T0) -> Path:
    """A 20 Hz tension log of ``n`` samples (a gentle sine, so a few cycles are counted)."""
    t = t0_ns + np.arange(n, dtype=np.int64) * 50_000_000
    v = 3000.0 + 500.0 * np.sin(np.arange(n) * 0.7)
    with LogWriter(path) as w:
        w.write_series([Series(buoy, "tension", t, v[None, :])], block_ns=10**9)
    return path


def test_replay_html_of_a_log_without_damage_rate(tmp_path, capsys):
    # a 2 s log accrues no damage rate: its report holds null for remaining life, which the
    # HTML renderer must take as "not available" instead of failing with a traceback
    log = tiny_log(tmp_path / "a.mcap")
    assert main(["replay", str(log), "--report", str(tmp_path / "r.json"),
                 "--html", str(tmp_path / "r.html")]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["components"]["conductor"]["remaining_life_days"] is None
    assert "n/a" in (tmp_path / "r.html").read_text()
    capsys.readouterr()
    # and `buoymon report` renders the same JSON again
    assert main(["report", str(tmp_path / "r.json"), "-o", str(tmp_path / "again.html")]) == 0
    # a missing sample count is still named, not read as NaN
    report["samples"]["tension"].pop("accepted")
    (tmp_path / "bad.json").write_text(json.dumps(report))
    assert main(["report", str(tmp_path / "bad.json")]) == 2
    assert "samples.tension.accepted = None" in capsys.readouterr().err
