"""docs/ARCHITECTURE.md places every production module, and names none that is gone.

The doc's "## Modules" list (lines ``- `pkg/mod.py`: job``) is compared with the tree both
ways, and every ``pkg/mod.py`` path named anywhere in the doc (the data path too) must exist.
"""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "ARCHITECTURE.md"
PACKAGES = ("models", "monitor", "replay")
TOP_INITS = {f"{p}/__init__.py" for p in PACKAGES}


def production_modules() -> set[str]:
    return {str(f.relative_to(REPO)) for p in PACKAGES for f in (REPO / p).rglob("*.py")
            if "__pycache__" not in f.parts} - TOP_INITS


def listed_modules(text: str) -> list[str]:
    section = text.split("\n## Modules\n", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"^- `([^`]+\.py)`: \S", section, flags=re.M)


def test_every_module_is_listed_once_and_every_listed_module_exists() -> None:
    listed = listed_modules(DOC.read_text())
    assert len(listed) == len(set(listed)), "a module listed twice"
    tree = production_modules()
    assert len(tree) > 100  # the tree was found: a glob that matched nothing would pass below
    assert sorted(tree - set(listed)) == [], "modules the doc does not place"
    assert sorted(set(listed) - tree) == [], "modules the doc names that do not exist"


def test_every_path_named_in_the_doc_exists() -> None:
    named = set(re.findall(r"\b((?:models|monitor|replay)/[\w/]+\.py)\b", DOC.read_text()))
    assert len(named) > 100
    assert sorted(p for p in named if not (REPO / p).is_file()) == []
