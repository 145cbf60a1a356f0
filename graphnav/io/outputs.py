"""Output directories: checked before any work starts, so a bad ``--out`` is a clean error."""

from __future__ import annotations

from pathlib import Path

from ..errors import GraphnavError


def ensure_dir(path: str | Path, flag: str = "--out") -> Path:
    """Create the directory ``path`` (and its parents) and return it. A path that exists and is not a
    directory, or cannot be created, is a :class:`GraphnavError` naming it and the flag."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise GraphnavError(f"{flag}: exists and is not a directory", where=str(p))
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a parent is a file, no permission, read-only file system...
        raise GraphnavError(f"{flag}: cannot create the directory ({exc.strerror or exc})", where=str(p)) from None
    return p
