"""Output paths of the command line, checked before any work: a command must not overwrite one
of its own input files, nor fail at the very end because the output is a folder."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Iterable


def check_output(path: str | os.PathLike, inputs: Iterable[str | os.PathLike], option: str
                 ) -> Path:
    """``path`` as a Path; ValueError naming ``option`` if it is a folder or an input file."""
    out = Path(path)
    if out.is_dir():
        raise ValueError(f"{option} {out}: is a folder, expected a file name")
    _check_writable_folder(out, option)
    if out.exists():
        for src in map(Path, inputs):
            if src.exists() and os.path.samefile(out, src):
                raise ValueError(f"{option} {out}: is the input file {src}; refusing to "
                                 "overwrite it")
    return out


def _check_writable_folder(out: Path, option: str) -> None:
    """ValueError naming ``option`` unless a file can be made where ``out`` goes: in its
    folder, or in the nearest existing one above it (writers create the missing ones). A
    replay would otherwise fail only at its very end, naming a temporary file."""
    folder = out.absolute().parent
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        raise ValueError(f"{option} {out}: {folder} is a file, not a folder")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise ValueError(f"{option} {out}: cannot write in {folder} ({exc.strerror})") from None
