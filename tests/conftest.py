"""Session-wide test settings."""

from __future__ import annotations

import os

import pytest


@pytest.fixture(autouse=True, scope="session")
def _session_model_cache(tmp_path_factory):
    """The model cache (monitor.model_cache) in a fresh directory for the session: tests
    never read or fill the user's cache, and the CLI subprocesses share one build."""
    old = os.environ.get("BUOYMON_CACHE_DIR")
    os.environ["BUOYMON_CACHE_DIR"] = str(tmp_path_factory.mktemp("model-cache"))
    yield
    if old is None:
        os.environ.pop("BUOYMON_CACHE_DIR", None)
    else:
        os.environ["BUOYMON_CACHE_DIR"] = old
