"""Error types. A bad record names the file, the line and the field.

Every failure that input or the environment can cause is a :class:`GraphnavError` (a bad record:
its subclass :class:`LogError`); the CLI prints it as ``graphnav: error: ...`` and exits with
:data:`EXIT_INPUT`. Anything else is an internal bug (:data:`EXIT_BUG`).
"""

from __future__ import annotations

from typing import Any

EXIT_OK = 0
EXIT_BUG = 1          # an internal error: a bug in graphnav
EXIT_INPUT = 2        # bad input, bad arguments or environment (file, address, option): the message says where
EXIT_INTERRUPTED = 130


class GraphnavError(Exception):
    """A failure caused by input or environment, not by a bug: ``where`` names the file, line,
    field, address or option at fault (``None`` when the message already says it all)."""

    def __init__(self, message: str, *, where: str | None = None) -> None:
        self.message = message
        self.where = where
        super().__init__(f"{where}: {message}" if where else message)


class LogError(GraphnavError, ValueError):
    """A malformed or inconsistent navigation-log record.

    ``str(err)`` reads ``FILE:LINE: field 'F': message`` (parts that are unknown are left out),
    so a user can jump straight to the offending record.
    """

    def __init__(
        self, message: str, *, file: str | None = None, line: int | None = None, field: str | None = None
    ) -> None:
        self.message = message
        self.file = file
        self.line = line
        self.field = field
        ValueError.__init__(self, self._render())
        self.where = self._where() or None

    def _where(self) -> str:
        parts = [str(self.file)] if self.file is not None else []
        if self.line is not None:
            parts.append(f"line {self.line}")
        if self.field:
            parts.append(f"field '{self.field}'")
        return ", ".join(parts)

    def _render(self) -> str:
        where = ""
        if self.file is not None:
            where = str(self.file)
            if self.line is not None:
                where += f":{self.line}"
        elif self.line is not None:
            where = f"line {self.line}"
        parts = [p for p in (where, f"field '{self.field}'" if self.field else "") if p]
        return (": ".join(parts) + ": " if parts else "") + self.message

    def located(self, *, file: str | None = None, line: int | None = None) -> LogError:
        """A copy of this error with the file/line filled in where still unknown."""
        return LogError(
            self.message,
            file=self.file if self.file is not None else file,
            line=self.line if self.line is not None else line,
            field=self.field,
        )


class AddressError(GraphnavError, ValueError):
    """A network address (``udp://HOST:PORT``, ``tcp://HOST:PORT``, a Dask scheduler) that cannot be
    parsed, resolved, bound or reached; ``where`` is the address as the user wrote it."""

    def __init__(self, address: str, message: str) -> None:
        super().__init__(message, where=address)


class MissingExtra(GraphnavError, ImportError):
    """An optional dependency is not installed: one line naming it and the extra that installs it."""

    def __init__(self, feature: str, package: str, extra: str) -> None:
        GraphnavError.__init__(self, f"{feature} needs the optional dependency {package}: "
                                     f"pip install 'graphnav[{extra}]'")
        self.package, self.extra = package, extra


EXTRAS = {"open3d": ("open3d", "open3d"), "distributed": ("dask", "dask"), "dask": ("dask", "dask"),
          "rosbags": ("rosbags", "ros"), "numba": ("numba", "fast"), "pypcd4": ("pypcd4", "pcd"),
          "kiss_icp": ("kiss-icp", "bench"), "nmea2000": ("nmea2000", "marine"), "tornado": ("tornado", "marine")}
"""Importable module -> (the distribution to install, the extra of pyproject.toml that installs it)."""


def require(module: str, feature: str) -> Any:
    """``import module`` (an optional dependency, a key of :data:`EXTRAS`), or :class:`MissingExtra`:
    ``"FEATURE needs the optional dependency open3d: pip install 'graphnav[open3d]'"``. The one
    helper every optional import site uses (numba's sites fall back to numpy when it is absent and
    call this only when numba was asked for by name)."""
    import importlib

    package, extra = EXTRAS[module.partition(".")[0]]
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtra(feature, package, extra) from None
