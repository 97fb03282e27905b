"""Atomic file writing: write to a temporary file in the target folder, then rename over the target.

Nothing half-written is ever left at the target path; on any error the temporary file is removed.
The final file gets the permissions of a newly created file (``0o666`` minus the umask, e.g.
``0o644`` with umask 022), not the ``0o600`` of the temporary file. A process killed between the
two steps leaves ``.<name>.<8 random characters>.tmp`` beside the target;
:func:`remove_stale_temps` removes exactly those names (nothing else) for a rerun.
"""
from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path


def current_umask() -> int:
    """The process umask (read from ``/proc/self/status`` where available, else set and restored)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    m = os.umask(0o022)
    os.umask(m)
    return m


def temp_name_pattern(name: str, suffix: str = ".tmp") -> re.Pattern[str]:
    """Regular expression of the temporary names :func:`atomic_path` creates for ``name``."""
    return re.compile(rf"^\.{re.escape(name)}\.[A-Za-z0-9_]{{8}}{re.escape(suffix)}$")


def remove_stale_temps(folder: str | Path, names: Iterable[str], suffix: str = ".tmp") -> list[Path]:
    """Remove the temporary files a killed :func:`atomic_path` left for the given final names.

    Only names of the exact pattern ``.<name>.XXXXXXXX<suffix>`` in ``folder`` are removed. Do not
    run two writers into one folder at once (one would remove the other's live temporary file).

    Returns
    -------
    list of Path
        The removed files.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    pats = [temp_name_pattern(n, suffix) for n in names]
    gone: list[Path] = []
    for p in folder.iterdir():
        if p.name.startswith(".") and p.is_file() and any(r.match(p.name) for r in pats):
            p.unlink(missing_ok=True)
            gone.append(p)
    return gone


@contextmanager
def atomic_path(path: str | Path, suffix: str = ".tmp", fsync: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on normal exit it replaces ``path``.

    Parameters
    ----------
    path : str or Path
        Final file (its folder is created). It gets mode ``0o666 & ~umask``.
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
        os.chmod(tmp, 0o666 & ~current_umask())
        if fsync:
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
