"""Lines of a plain or gzipped log file, read incrementally.

A corrupt or truncated compressed stream (``zlib.error``, ``EOFError``, ``gzip.BadGzipFile``) is a
:class:`~graphnav.errors.LogError` naming the file and the line reached. With ``lenient`` the lines
before it are kept, the truncation is noted (:attr:`Lines.truncated`, counted by the readers as
one skipped record) and a warning is logged.
"""

from __future__ import annotations

import gzip
import logging
import zlib
from collections.abc import Iterator
from pathlib import Path

from ..errors import LogError

log_ = logging.getLogger(__name__)

#: What reading a damaged gzip stream raises (``gzip.BadGzipFile`` is an ``OSError``).
READ_ERRORS = (OSError, EOFError, zlib.error)


def is_gzip(path: Path) -> bool:
    return path.name.lower().endswith(".gz")


class Lines:
    """``for lineno, raw in Lines(path, lenient=...)``: the file's lines (bytes, with their ``\\n``),
    numbered from 1, decompressed on the fly when the name ends in ``.gz``."""

    def __init__(self, path: str | Path, *, lenient: bool = False, quiet: bool = False) -> None:
        self.path = Path(path)
        self.lenient = lenient
        self.quiet = quiet  # lenient without the warning (a reader's first, probing pass)
        self.truncated: LogError | None = None
        self.count = 0

    def __iter__(self) -> Iterator[tuple[int, bytes]]:
        try:
            fh = gzip.open(self.path, "rb") if is_gzip(self.path) else open(self.path, "rb")
        except OSError as exc:
            raise LogError(f"cannot read: {exc.strerror or exc}", file=str(self.path)) from None
        with fh:
            while True:
                try:
                    raw = fh.readline()
                except READ_ERRORS as exc:
                    self._damaged(exc)
                    return
                if not raw:
                    return
                self.count += 1
                yield self.count, raw

    def _damaged(self, exc: BaseException) -> None:
        what = "compressed stream is corrupt or truncated" if is_gzip(self.path) else "read failed"
        err = LogError(f"{what} after line {self.count} ({exc.__class__.__name__}: {str(exc)[:120]})",
                       file=str(self.path), line=self.count + 1)
        if not self.lenient:
            raise err from None
        self.truncated = err
        if not self.quiet:
            log_.warning("%s; keeping the %d lines before it", err, self.count)


def note_truncation(meta: dict, lines: Lines | None, skipped: list[str]) -> None:
    """Lenient readers: a truncated stream counts as one skipped record and is named in ``meta``."""
    if lines is not None and lines.truncated is not None:
        skipped.append(str(lines.truncated))
        meta["truncated"] = str(lines.truncated)
