"""Error types. A bad record names the file, the line and the field."""

from __future__ import annotations


class LogError(ValueError):
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
        super().__init__(self._render())

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
