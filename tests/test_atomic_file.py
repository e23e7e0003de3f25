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
