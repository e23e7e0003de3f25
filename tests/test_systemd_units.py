"""The shipped systemd units (packaging/systemd/) are valid and hardened: `systemd-analyze
verify` accepts them, `systemd-analyze security --offline=true` rates each at most 3.0
(the daemon's unit was 8.5 "EXPOSED" before), and the same units stripped of their
hardening section score above it (the check can fail)."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
UNITS = REPO / "packaging" / "systemd"
ANALYZE = shutil.which("systemd-analyze")
pytestmark = pytest.mark.skipif(ANALYZE is None, reason="systemd-analyze is not installed")
MAX_EXPOSURE = 3.0


def exposure(unit: Path) -> float:
    out = subprocess.run([ANALYZE, "security", "--offline=true", "--no-pager", str(unit)],
                         capture_output=True, text=True, timeout=60)
    m = re.search(r"Overall exposure level for \S+: (\d+\.\d+)", out.stdout)
    assert m, out.stdout + out.stderr
    return float(m.group(1))


def installed(tmp_path: Path) -> list[Path]:
    """The units as installed here: ExecStart pointing at this environment's buoymon (verify
    checks that the command exists)."""
    exe = Path(sys.executable).parent / "buoymon"
    if not exe.exists():
        pytest.skip(f"{exe} not installed")
    out = []
    for unit in sorted(UNITS.glob("*.service")):
        dest = tmp_path / unit.name
        dest.write_text(unit.read_text().replace("/opt/buoymon/.venv/bin/buoymon", str(exe)))
        out.append(dest)
    return out


def test_units_verify(tmp_path):
    units = installed(tmp_path)
    assert [u.name for u in units] == ["buoymon-bridge.service", "buoymon.service"]
    out = subprocess.run([ANALYZE, "verify", *map(str, units)], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0 and not out.stderr.strip(), out.stderr


@pytest.mark.parametrize("name", ["buoymon.service", "buoymon-bridge.service"])
def test_each_unit_is_hardened_to_at_most_3(name, tmp_path):
    unit = UNITS / name
    assert exposure(unit) <= MAX_EXPOSURE
    # the same unit without its hardening section is exposed: the figure is the hardening's
    text = unit.read_text()
    head, rest = text.split("# --- hardening", 1)
    bare = tmp_path / name
    bare.write_text(head + "[Install]" + rest.split("[Install]", 1)[1])
    assert exposure(bare) > MAX_EXPOSURE + 3.0


def test_the_bridge_reaches_serial_devices_through_dialout_and_nothing_else():
    text = (UNITS / "buoymon-bridge.service").read_text()
    keys = re.findall(r"^(\w+)=(.*)$", text, re.M)
    assert ("SupplementaryGroups", "dialout") in keys and ("DevicePolicy", "closed") in keys
    assert sorted(v for k, v in keys if k == "DeviceAllow") == [
        "char-ttyACM rw", "char-ttyS rw", "char-ttyUSB rw"]
    assert ("After", "buoymon.service") in keys and ("Restart", "always") in keys
    # the block encoder runs numba kernels: executable memory allowed, a writable cache
    assert "MemoryDenyWriteExecute" not in dict(keys)
    assert ("Environment", "NUMBA_CACHE_DIR=/var/cache/buoymon-bridge/numba") in keys
    assert ("CacheDirectory", "buoymon-bridge") in keys
    daemon = dict(re.findall(r"^(\w+)=(.*)$", (UNITS / "buoymon.service").read_text(), re.M))
    assert daemon["PrivateDevices"] == "yes" and daemon["Type"] == "notify"
