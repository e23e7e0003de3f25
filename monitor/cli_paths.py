"""Output paths of the command line, checked before any work: a command must not overwrite one
of its own input files, nor fail at the very end because the output is a folder."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable


def check_output(path: str | os.PathLike, inputs: Iterable[str | os.PathLike], option: str
                 ) -> Path:
    """``path`` as a Path; ValueError naming ``option`` if it is a folder or an input file."""
    out = Path(path)
    if out.is_dir():
        raise ValueError(f"{option} {out}: is a folder, expected a file name")
    if out.exists():
        for src in map(Path, inputs):
            if src.exists() and os.path.samefile(out, src):
                raise ValueError(f"{option} {out}: is the input file {src}; refusing to "
                                 "overwrite it")
    return out
