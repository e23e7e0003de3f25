"""The first run after an install says that it compiles; a run with a warm cache says
nothing (real processes, numba's real disk cache in a private directory)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from monitor.first_run import MESSAGE, COMPILE_SECONDS

ROOT = Path(__file__).resolve().parents[1]

KERNEL = '''
import numba

@numba.njit(cache=True)
def twice(x):
    return 2.0 * x
'''

RUN = '''
import sys
sys.path.insert(0, sys.argv[1])
from monitor.first_run import announce_compiles
announce_compiles()
announce_compiles()  # a nested command: still one message
import kernel
print(kernel.twice(21.0))
'''


def _run(tmp_path: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    return subprocess.run([sys.executable, "-c", RUN, str(tmp_path / "src")], env=env,
                          capture_output=True, text=True, timeout=120)


def test_compile_is_announced_once_and_only_on_a_cold_cache(tmp_path):
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "kernel.py").write_text(KERNEL)
    cold = _run(tmp_path)
    assert cold.returncode == 0 and cold.stdout.strip() == "42.0", cold.stderr
    assert cold.stderr.count("compiling the numerical kernels") == 1
    assert MESSAGE.format(seconds=COMPILE_SECONDS) in cold.stderr
    warm = _run(tmp_path)  # numba loads the kernel from its disk cache: no compile, no word
    assert warm.returncode == 0 and warm.stdout.strip() == "42.0"
    assert "compiling" not in warm.stderr, warm.stderr
