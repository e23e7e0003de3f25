"""monitor.memory: the JIT compiler's resident pages are handed back, the kernels still run."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from monitor.memory import compiler_mappings

REPO = Path(__file__).resolve().parents[1]


def test_compiler_mappings_parses_proc_maps(tmp_path):
    maps = tmp_path / "maps"
    maps.write_text(
        "7f0000000000-7f0000001000 r--p 00000000 08:01 42 /venv/llvmlite/binding/libllvmlite.so\n"
        "7f0000001000-7f0000009000 r-xp 00001000 08:01 42 /venv/llvmlite/binding/libllvmlite.so\n"
        "7f1000000000-7f1000002000 rw-p 00000000 00:00 0 \n"
        "7f2000000000-7f2000001000 r-xp 00000000 08:01 7 /usr/lib/libc.so.6\n")
    assert compiler_mappings(str(maps)) == [(0x7F0000000000, 0x7F0000001000),
                                            (0x7F0000001000, 0x7F0000009000)]
    assert compiler_mappings(str(tmp_path / "absent")) == []


@pytest.mark.integration  # a fresh interpreter
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux only")
def test_release_drops_the_compiler_pages_and_kernels_still_run():
    code = textwrap.dedent("""
        import json
        import numpy as np
        from models.fatigue import MinerAccumulator, SNCurve, StreamingRainflow
        from monitor.memory import release_compiler_pages

        def llvm_kb():
            # (resident, private clean) kB: pages other processes also map (say, the test
            # runner's own numba) are shared, and the kernel leaves those where they are, as
            # it keeps modified (dirty) ones without swap
            kb, cur = [0, 0], False
            for line in open("/proc/self/smaps"):
                if "-" in line.split(" ", 1)[0]:
                    cur = "libllvmlite" in line
                elif cur and line.startswith("Rss:"):
                    kb[0] += int(line.split()[1])
                elif cur and line.startswith("Private_Clean:"):
                    kb[1] += int(line.split()[1])
            return kb

        x = 1e6 * np.sin(np.arange(2000) / 5.0)
        rf, miner = StreamingRainflow(), MinerAccumulator(SNCurve.vaps_copper())
        r, m, c = rf.feed(x[:1000])
        miner.add_cycles(r, m, c)
        before = llvm_kb()
        advised = release_compiler_pages()
        after = llvm_kb()
        r, m, c = rf.feed(x[1000:])  # the compiled kernels need no compiler
        miner.add_cycles(r, m, c)
        print(json.dumps({"before": before, "after": after, "advised": advised,
                          "cycles": miner.total_cycles, "damage": miner.damage_committed}))
    """)
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                         text=True, check=True, env={"PYTHONPATH": str(REPO), "PATH": ""})
    res = __import__("json").loads(out.stdout.strip().splitlines()[-1])
    if res["advised"] == 0:
        pytest.skip("madvise(MADV_PAGEOUT) unsupported here (Linux < 5.4)")
    (rss_before, private_before), (rss_after, private_after) = res["before"], res["after"]
    assert rss_before > 20_000  # kB: LLVM ran to load the kernels
    assert private_after < private_before / 4 + 256  # this process's own pages went back
    assert rss_after <= rss_before - (private_before - private_after) + 256
    # the same numbers as without the release
    import numpy as np

    from models.fatigue import MinerAccumulator, SNCurve, StreamingRainflow
    x = 1e6 * np.sin(np.arange(2000) / 5.0)
    rf, miner = StreamingRainflow(), MinerAccumulator(SNCurve.vaps_copper())
    for part in (x[:1000], x[1000:]):
        r, m, c = rf.feed(part)
        miner.add_cycles(r, m, c)
    assert res["cycles"] == miner.total_cycles == 60
    assert res["damage"] == miner.damage_committed > 0
