"""The on-disk model cache: a build is reused across processes, never when stale or damaged."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from monitor import model_cache

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Inputs:
    depth_m: float
    name: str


def _builder(calls: list, value):
    def build():
        calls.append(1)
        return value
    return build


def test_a_build_is_saved_and_reused(tmp_path, monkeypatch):
    monkeypatch.setenv("BUOYMON_CACHE_DIR", str(tmp_path / "c"))
    calls: list = []
    value = {"table": np.linspace(0.0, 1.0, 7), "n": 3}
    first = model_cache.cached("demo", Inputs(23.0, "a"), _builder(calls, value))
    again = model_cache.cached("demo", Inputs(23.0, "a"), _builder(calls, {"other": 1}))
    assert len(calls) == 1 and again is not first
    assert np.array_equal(again["table"], value["table"]) and again["n"] == 3
    (entry,) = (tmp_path / "c").iterdir()
    assert entry.name.startswith("demo-") and (tmp_path / "c").stat().st_mode & 0o077 == 0
    # other inputs, another entry
    assert model_cache.cached("demo", Inputs(23.5, "a"), _builder(calls, 5)) == 5
    assert len(calls) == 2 and len(list((tmp_path / "c").iterdir())) == 2


def test_a_damaged_entry_is_rebuilt_and_rewritten(tmp_path, monkeypatch):
    monkeypatch.setenv("BUOYMON_CACHE_DIR", str(tmp_path))
    calls: list = []
    model_cache.cached("demo", Inputs(1.0, "x"), _builder(calls, [1, 2]))
    (entry,) = tmp_path.iterdir()
    entry.write_bytes(entry.read_bytes()[:5])
    assert model_cache.cached("demo", Inputs(1.0, "x"), _builder(calls, [1, 2])) == [1, 2]
    assert len(calls) == 2
    assert model_cache.cached("demo", Inputs(1.0, "x"), _builder(calls, None)) == [1, 2]
    assert len(calls) == 2


def test_turned_off_or_unwritable_only_costs_the_build(tmp_path, monkeypatch):
    calls: list = []
    monkeypatch.setenv("BUOYMON_CACHE_DIR", "")
    assert model_cache.cache_dir() is None
    assert model_cache.cached("demo", Inputs(1.0, "x"), _builder(calls, 7)) == 7
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("BUOYMON_CACHE_DIR", str(blocker / "sub"))
    assert model_cache.cached("demo", Inputs(1.0, "x"), _builder(calls, 7)) == 7
    assert len(calls) == 2


def test_default_directory_follows_xdg(tmp_path, monkeypatch):
    monkeypatch.delenv("BUOYMON_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert model_cache.cache_dir() == tmp_path / "buoymon"


def test_the_cached_estimator_gives_the_same_bits_in_another_process(tmp_path):
    """The catenary estimator built in one process and loaded from the cache in the next
    estimates the same tensions to the bit as a fresh build."""
    script = (
        "import numpy as np, time\n"
        "from monitor.config import default_config\n"
        "from monitor.load_source import build_estimator\n"
        "t = time.process_time()\n"
        "est = build_estimator(default_config())\n"
        "dt = time.process_time() - t\n"
        "n = 3000\n"
        "k = np.arange(n)\n"
        "f = {'accel_x_mps2': 0.3 * np.sin(k / 9.0), 'accel_y_mps2': 0.1 * np.cos(k / 7.0),\n"
        "     'accel_z_mps2': 0.8 * np.sin(k / 5.0)}\n"
        "t_ns, v, _ = est.feed(k.astype(np.int64) * 100_000_000, f)\n"
        "print(dt, v.shape[0], v.tobytes().hex())\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT), "BUOYMON_CACHE_DIR": str(tmp_path)}

    def run(cache: bool):
        e = env if cache else {**env, "BUOYMON_CACHE_DIR": ""}
        out = subprocess.run([sys.executable, "-c", script], env=e, capture_output=True,
                             text=True, check=True).stdout.split()
        return float(out[0]), int(out[1]), out[2]

    fresh = run(cache=False)
    run(cache=True)  # writes the entry
    (entry,) = tmp_path.iterdir()
    assert entry.name.startswith("estimator-")
    loaded = run(cache=True)
    assert loaded[1] == fresh[1] > 100 and loaded[2] == fresh[2]
    assert loaded[0] < fresh[0]  # the catenary solves are skipped


def test_a_change_to_the_builders_module_invalidates_its_entries(tmp_path, monkeypatch):
    monkeypatch.setenv("BUOYMON_CACHE_DIR", str(tmp_path / "c"))
    src = tmp_path / "builder_mod.py"
    src.write_text("def build():\n    return 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import builder_mod

    model_cache._code_version.cache_clear()
    try:
        assert model_cache.cached("demo", Inputs(1.0, "x"), builder_mod.build) == 1
        assert model_cache.cached("demo", Inputs(1.0, "x"), builder_mod.build) == 1
        src.write_text("def build():\n    return 22\n")  # same module, new source
        importlib.reload(builder_mod)
        model_cache._code_version.cache_clear()
        assert model_cache.cached("demo", Inputs(1.0, "x"), builder_mod.build) == 22
    finally:
        model_cache._code_version.cache_clear()
        sys.modules.pop("builder_mod", None)


def test_a_change_to_the_models_source_invalidates_every_entry(tmp_path, monkeypatch):
    assert (model_cache._MODELS / "catenary" / "tension_table.py").is_file()
    src = tmp_path / "models"
    (src / "catenary").mkdir(parents=True)
    (src / "catenary" / "table.py").write_text("A = 1\n")  # a subpackage's module counts too
    monkeypatch.setattr(model_cache, "_MODELS", src)
    monkeypatch.setenv("BUOYMON_CACHE_DIR", str(tmp_path / "c"))
    calls: list = []
    model_cache._code_version.cache_clear()
    try:
        model_cache.cached("demo", Inputs(1.0, "x"), _builder(calls, 1))
        model_cache.cached("demo", Inputs(1.0, "x"), _builder(calls, 1))
        (src / "catenary" / "table.py").write_text("A = 2\n")
        model_cache._code_version.cache_clear()
        assert model_cache.cached("demo", Inputs(1.0, "x"), _builder(calls, 2)) == 2
    finally:
        model_cache._code_version.cache_clear()
    assert len(calls) == 2


def test_a_build_without_a_source_file_is_not_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("BUOYMON_CACHE_DIR", str(tmp_path / "c"))
    calls: list = []
    build = _builder(calls, 5)
    build.__module__ = "__no_such_module__"
    assert model_cache.cached("demo", Inputs(1.0, "x"), build) == 5
    assert model_cache.cached("demo", Inputs(1.0, "x"), build) == 5
    assert len(calls) == 2 and not (tmp_path / "c").exists()
