"""Where a report came from: date, graphnav version (and git revision), Python, the command line, the log's SHA-256."""

from __future__ import annotations

import datetime as _dt
import hashlib
import shlex
import subprocess
import sys
from pathlib import Path


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        v = version("graphnav")
    except PackageNotFoundError:
        v = "unknown"
    src = Path(__file__).resolve().parents[3]
    if not (src / "pyproject.toml").exists() or not (src / ".git").exists():
        return v  # an installed package: no checkout to describe
    try:
        rev = subprocess.run(["git", "-C", str(src), "describe", "--always", "--dirty"], capture_output=True,
                             text=True, timeout=10)
        if rev.returncode == 0 and rev.stdout.strip():
            v += f" (git {rev.stdout.strip()})"
    except (OSError, subprocess.SubprocessError):
        pass
    return v


def _digest(path: Path) -> tuple[int, str]:
    """Size in bytes and SHA-256 of a file, or of a directory's files (relative names and contents,
    in sorted order)."""
    h = hashlib.sha256()
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    size = 0
    for f in files:
        if f is not path:
            h.update(str(f.relative_to(path)).encode() + b"\0")
        with open(f, "rb") as fh:
            for chunk in iter(lambda fh=fh: fh.read(1 << 20), b""):
                h.update(chunk)
                size += len(chunk)
    return size, h.hexdigest()


def provenance(log_path: str | Path | None, command: str | None = None) -> dict[str, str]:
    """Where a report came from: date (UTC), graphnav version (and git revision when run from a
    checkout), Python, the command line, and the log with its size and SHA-256."""
    out = {"date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
           "graphnav": _version(),
           "python": sys.version.split()[0],
           "command": command or f"(not given; the process: {shlex.join(sys.argv)})"}
    if log_path is not None:
        p = Path(log_path)
        out["log"] = str(log_path)
        if p.exists():
            size, sha = _digest(p)
            out["log size"] = f"{size:,} bytes" + (" (directory)" if p.is_dir() else "")
            out["log SHA-256"] = sha
    return out

