"""Lines of a plain or gzipped log file, read incrementally.

A corrupt or truncated compressed stream (``zlib.error``, ``EOFError``, ``gzip.BadGzipFile``) is a
:class:`~graphnav.errors.LogError` naming the file and the line reached. With ``lenient`` the lines
before it are kept, the truncation is noted (:attr:`Lines.truncated`, counted by the readers as
one skipped record) and a warning is logged.

Bounds: a line longer than ``max_line`` bytes (default :data:`MAX_LINE_BYTES`, as the CARMEN
reader's) is an error naming its number, read in pieces so that a file without newlines cannot
exhaust memory; a compressed file stops with an error once it has inflated to more than
``max_bytes`` (default :data:`MAX_INFLATED_BYTES`), so a small ``.gz`` cannot grow without bound.
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
MAX_LINE_BYTES = 4_000_000
"""The longest line a text reader takes by default (an NMEA sentence is 82 characters)."""
MAX_INFLATED_BYTES = 8 << 30
"""The most bytes a compressed text log may inflate to (8 GiB)."""


def is_gzip(path: Path) -> bool:
    return path.name.lower().endswith(".gz")


class Lines:
    """``for lineno, raw in Lines(path, lenient=...)``: the file's lines (bytes, with their ``\\n``),
    numbered from 1, decompressed on the fly when the name ends in ``.gz``."""

    def __init__(self, path: str | Path, *, lenient: bool = False, quiet: bool = False,
                 max_line: int = MAX_LINE_BYTES, max_bytes: int = MAX_INFLATED_BYTES) -> None:
        self.path = Path(path)
        self.lenient = lenient
        self.quiet = quiet  # lenient without the warning (a reader's first, probing pass)
        self.truncated: LogError | None = None
        self.count = 0
        self.max_line = max_line
        self.max_bytes = max_bytes
        self.bytes = 0
        self.too_long: list[str] = []  # lenient: the over-long lines skipped (their errors)

    def __iter__(self) -> Iterator[tuple[int, bytes]]:
        try:
            fh = gzip.open(self.path, "rb") if is_gzip(self.path) else open(self.path, "rb")
        except OSError as exc:
            raise LogError(f"cannot read: {exc.strerror or exc}", file=str(self.path)) from None
        with fh:
            while True:
                try:
                    raw = fh.readline(self.max_line + 1)
                    if len(raw) > self.max_line and not raw.endswith(b"\n"):
                        raw = self._too_long(fh)
                except READ_ERRORS as exc:
                    self._damaged(exc)
                    return
                if not raw:
                    return
                self.count += 1
                self.bytes += len(raw)
                if self.bytes > self.max_bytes:
                    raise LogError(f"inflates to more than {self.max_bytes} bytes: refused (a decompression bomb?)",
                                   file=str(self.path), line=self.count)
                yield self.count, raw

    def _too_long(self, fh) -> bytes:  # noqa: ANN001
        """Skip the rest of an over-long line (in pieces); strict: an error, lenient: an empty line
        (a comment to the readers) after a warning. Returns what stands for the line."""
        skipped = 0
        while True:
            piece = fh.readline(self.max_line)
            skipped += len(piece)
            if not piece or piece.endswith(b"\n") or self.bytes + skipped > self.max_bytes:
                break
        self.bytes += skipped
        err = LogError(f"line longer than {self.max_line} bytes", file=str(self.path), line=self.count + 1)
        if not self.lenient:
            raise err
        self.too_long.append(str(err))
        if not self.quiet:
            log_.warning("%s: skipped", err)
        return b"\n"

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
    """Lenient readers: a truncated stream counts as one skipped record and is named in ``meta``; so
    does each over-long line."""
    if lines is not None:
        skipped.extend(lines.too_long)
    if lines is not None and lines.truncated is not None:
        skipped.append(str(lines.truncated))
        meta["truncated"] = str(lines.truncated)
