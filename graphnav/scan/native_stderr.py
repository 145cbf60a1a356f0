"""The C++ libraries' own messages (small_gicp writes ``warning: ...`` lines to the process's
stderr, fd 2, beside Python) captured and counted instead of reaching the terminal raw.

``with NativeWarnings("small_gicp") as w: ...`` redirects fd 2 to a temporary file for the block;
after it ``w.lines`` holds the distinct lines (at most :data:`KEEP`), ``w.count`` how many there
were, and one ``logging`` warning of the ``graphnav.native`` logger summarises them (so they show
once, with the library's name, and ``--json`` output stays clean).
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
from types import TracebackType

log = logging.getLogger("graphnav.native")
KEEP = 5
MAX_READ = 1 << 16


class NativeWarnings(contextlib.AbstractContextManager):
    """Capture fd 2 for a block (see the module doc)."""

    def __init__(self, library: str) -> None:
        self.library = library
        self.count = 0
        self.lines: list[str] = []
        self._saved: int | None = None
        self._tmp = None

    def __enter__(self) -> NativeWarnings:
        try:
            sys.stderr.flush()
            self._tmp = tempfile.TemporaryFile()
            self._saved = os.dup(2)
            os.dup2(self._tmp.fileno(), 2)
        except (OSError, ValueError):  # no fd 2 (embedded interpreters): leave it alone
            self._saved = None
        return self

    def __exit__(self, typ: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        if self._saved is None:
            return
        os.dup2(self._saved, 2)
        os.close(self._saved)
        self._tmp.seek(0)
        text = self._tmp.read(MAX_READ).decode("utf-8", "replace")
        self._tmp.close()
        lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
        self.count = len(lines)
        self.lines = list(dict.fromkeys(lines))[:KEEP]
        if self.count:
            log.warning("%s: %d message(s), e.g. %r", self.library, self.count, self.lines[0][:200])
