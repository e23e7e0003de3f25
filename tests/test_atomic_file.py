"""monitor.atomic_file: whole-file replacement with ordinary permissions."""

from __future__ import annotations

import os
import stat

from monitor.atomic_file import atomic_write_bytes, atomic_write_text


def test_new_files_get_the_umask_permissions_and_replacements_keep_theirs(tmp_path):
    old = os.umask(0o027)
    try:
        p = tmp_path / "sub" / "report.json"
        atomic_write_text(p, '{"a": 1}')
        assert p.read_text() == '{"a": 1}' and stat.S_IMODE(p.stat().st_mode) == 0o640
        p.chmod(0o604)
        atomic_write_bytes(p, b"\x00\x01")
        assert p.read_bytes() == b"\x00\x01" and stat.S_IMODE(p.stat().st_mode) == 0o604
        assert [f.name for f in p.parent.iterdir()] == ["report.json"]  # no temporary left
    finally:
        os.umask(old)


def _tiny_disk(path) -> bool:
    """A full 64 kB tmpfs at ``path`` (root only): a real full disk."""
    import subprocess

    path.mkdir()
    if os.geteuid() != 0 or subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(path)],
            capture_output=True).returncode != 0:
        return False
    (path / "fill").write_bytes(b"\0" * 60 * 1024)
    return True


def test_buoymon_replay_on_a_full_disk_names_the_report_it_could_not_write(tmp_path, capsys):
    """On a full disk `buoymon replay --report` said only "[Errno 28] No space left on
    device": the write fails with no file name, and the operator could not tell which of
    the report, state or HTML output it was. Now the message names it, and nothing is left
    half-written."""
    import subprocess

    import pytest

    from monitor.cli import main

    full = tmp_path / "full"
    if not _tiny_disk(full):
        pytest.skip("mounting a tmpfs needs root")
    try:
        log = tmp_path / "a.mcap"
        assert main(["simulate", "-o", str(log), "--hours", "0.05", "--hs", "1", "--tp", "6",
                     "--seed", "1"]) == 0
        capsys.readouterr()
        report = full / "report.json"
        assert main(["replay", str(log), "--no-progress", "--report", str(report)]) == 1
        err = capsys.readouterr().err
        assert f"buoymon replay: [Errno 28] No space left on device: '{report}'" in err
        assert sorted(f.name for f in full.iterdir()) == ["fill"]
        # the HTML report's PNGs: one was left cut short at the disk's last 4 kB
        html = full / "r.html"
        assert main(["replay", str(log), "--no-progress", "--html", str(html)]) == 1
        assert "No space left on device: '" in capsys.readouterr().err
        for png in full.glob("*.png"):  # those written whole (none here) are whole PNGs
            assert png.read_bytes().endswith(b"IEND\xaeB`\x82"), png
        assert not [f for f in full.iterdir() if f.name.startswith(".")]  # no temporary
        assert not html.exists()
        # the Rerun recording: a traceback from Rerun's flush at the end
        rrd = full / "r.rrd"
        assert main(["replay", str(log), "--no-progress", "--rrd", str(rrd)]) == 1
        err = capsys.readouterr().err
        assert "buoymon replay: Rerun recording not written whole: " in err
        # what the full disk took is kept under a name that says so, never as r.rrd
        partial = full / "r.partial.rrd"
        assert f"replay: the Rerun recording is partial, kept as {partial} " in err
        assert partial.exists() and not rrd.exists()
        # a disk full to the last byte: Rerun cannot even open the recording (was exit 2, a
        # "bad option", and an empty r.rrd left behind)
        partial.unlink()
        try:
            with open(full / "last", "wb") as f:
                while True:
                    f.write(b"\0" * 512)
                    f.flush()
        except OSError:  # full
            pass
        code = main(["replay", str(log), "--no-progress", "--rrd", str(rrd)])
        err = capsys.readouterr().err
        assert code == 1, err
        assert f"replay: --rrd {rrd}: cannot write the recording: " in err
        assert not rrd.exists() and not (full / "r.partial.rrd").exists()
    finally:
        subprocess.run(["umount", str(full)], check=True)
