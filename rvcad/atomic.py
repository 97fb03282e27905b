"""Atomic file writing: write to a temporary file in the target folder, then rename over the target.

Nothing half-written is ever left at the target path; on any error the temporary file is removed.
"""
from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def atomic_path(path: str | Path, suffix: str = ".tmp", fsync: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on normal exit it replaces ``path``.

    Parameters
    ----------
    path : str or Path
        Final file (its folder is created).
    suffix : str
        Suffix of the temporary name (e.g. ``".png"`` where a writer infers the format from it).
    fsync : bool
        Flush the temporary file to disk before the rename (a crash then leaves the old or the new
        file, never an empty one; costs a disk sync per file).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        if fsync:
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
