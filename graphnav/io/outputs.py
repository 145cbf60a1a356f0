"""Output files and directories: atomic writes, and output directories that never mix two runs.

* :func:`atomic_path` / :func:`atomic_open` / :func:`write_text_atomic`: a file is written under a
  temporary name in its own directory (``.tmp-PID-NAME``, so the suffix -- and the format that
  numpy/matplotlib infer from it -- is kept), flushed to disk and renamed onto the final name with
  :func:`os.replace` (atomic on POSIX and Windows): a reader sees the old file or the new one,
  never half of one, and a crash leaves at most a ``.tmp-*`` file behind.
* :class:`OutDir`: the ``--out DIR`` of a command. Every file a command writes there is first
  recorded in ``DIR/.graphnav-outputs.json`` (the manifest: this directory's files that graphnav
  wrote). A directory that is not empty is refused unless ``--overwrite`` is given; then the
  files the manifest lists (and ``.tmp-*`` leftovers) are deleted before the run, and nothing
  else: files graphnav did not write stay, sub-directories are never touched.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import stat
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from ..errors import GraphnavError

log = logging.getLogger("graphnav.outputs")
MANIFEST = ".graphnav-outputs.json"
TMP_PREFIX = ".tmp-"


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


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def file_kind(path: str | Path) -> str | None:
    """What is at ``path`` without following a symlink: None (nothing), ``"file"`` (a regular file),
    or what else it is (``"symbolic link"``, ``"directory"``, ``"FIFO"``, ``"device"``, ``"socket"``)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return None
    except OSError:
        return "unreadable entry"
    if stat.S_ISREG(mode):
        return "file"
    if stat.S_ISLNK(mode):
        return "symbolic link"
    if stat.S_ISDIR(mode):
        return "directory"
    if stat.S_ISFIFO(mode):
        return "FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "device"
    return "socket" if stat.S_ISSOCK(mode) else "special file"


def check_replaceable(path: str | Path, *, overwrite: bool, flag: str = "--out") -> None:
    """A :class:`GraphnavError` naming ``flag`` and ``path`` unless a file may be written there: nothing
    there, or a regular file and ``overwrite`` (a symlink, FIFO, device or directory is never replaced);
    the parent directory must exist."""
    kind = file_kind(path)
    if kind is not None and kind != "file":
        raise GraphnavError(f"{flag}: exists and is a {kind}, not a regular file; graphnav replaces only regular "
                            "files", where=str(path))
    if kind == "file" and not overwrite:
        raise GraphnavError(f"{flag}: the file exists; pass --overwrite to replace it", where=str(path))
    if not Path(path).parent.is_dir():
        raise GraphnavError(f"{flag}: the directory does not exist", where=str(Path(path).parent))


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same name ending); when the block ends normally the
    file there is synced and renamed onto ``path``; on an exception it is removed. Only a regular
    file (or nothing) at ``path`` is replaced: a symlink, FIFO, device or directory there is a
    :class:`GraphnavError`."""
    path = Path(path)
    kind = file_kind(path)
    if kind not in (None, "file"):
        raise GraphnavError(f"exists and is a {kind}, not a regular file: not replaced", where=str(path))
    tmp = path.with_name(f"{TMP_PREFIX}{os.getpid()}-{path.name}")
    try:
        yield tmp
        _fsync(tmp)
        if file_kind(path) not in (None, "file"):
            raise GraphnavError("became a non-regular file while being written: not replaced", where=str(path))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """``open(path, mode)`` that replaces ``path`` atomically when the block ends normally."""
    if not mode.startswith("w"):
        raise ValueError(f"atomic_open writes a whole file: mode {mode!r} must start with 'w'")
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh


def write_text_atomic(path: str | Path, text: str) -> Path:
    with atomic_open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    return Path(path)


class OutDir:
    """The output directory of one command run (see the module docstring).

    ``overwrite``: replace what graphnav wrote there before (``--overwrite``); without it a
    non-empty directory is an error. ``own_ok``: a directory that holds only files the manifest
    lists (a previous run's, nothing of the user's) is replaced without ``--overwrite``
    (``graphnav demo`` uses this for its own ``out/demo``). ``file(name)`` records ``name`` in the
    manifest and returns its path; ``write_text(name, text)`` also writes it atomically.
    """

    def __init__(self, path: str | Path, *, command: str, overwrite: bool = False, own_ok: bool = False,
                 flag: str = "--out") -> None:
        self.created = not Path(path).exists()
        self.path = ensure_dir(path, flag)
        self.command = command
        self.files: list[str] = []
        self._lock = _lock_dir(self.path, flag)
        previous = self._read_manifest()
        present = sorted(e.name for e in self.path.iterdir() if e.name != MANIFEST)
        if present:
            ours = set(previous)
            foreign = [n for n in present if n not in ours and not n.startswith(TMP_PREFIX)]
            if not overwrite and (foreign or not own_ok):
                listed = ", ".join(present[:5]) + (f", ... ({len(present)} entries)" if len(present) > 5 else "")
                raise GraphnavError(
                    f"{flag}: the directory is not empty ({listed}); pass --overwrite to replace the files "
                    "graphnav wrote there (other files are left alone), or choose another directory",
                    where=str(self.path))
            removed = self._clear(previous)
            if removed:
                log.info("%s: removed %d file(s) of the previous run (%s)", self.path, len(removed),
                         ", ".join(removed[:5]) + (" ..." if len(removed) > 5 else ""))
        self._write_manifest()

    def _read_manifest(self) -> list[str]:
        p = self.path / MANIFEST
        try:
            obj = json.loads(p.read_text(encoding="utf-8"))
            names = obj.get("files", []) if isinstance(obj, dict) else []
        except (OSError, ValueError):
            return []
        return [n for n in names if isinstance(n, str) and _plain(n)]

    def _clear(self, previous: list[str]) -> list[str]:
        """Delete the manifest's files and ``.tmp-*`` leftovers (regular files directly in the directory)."""
        removed = []
        tmp = [e.name for e in self.path.iterdir() if e.name.startswith(TMP_PREFIX)]
        for name in [*previous, *tmp]:
            p = self.path / name
            if p.is_file() or p.is_symlink():
                p.unlink()
                removed.append(name)
        return removed

    def _write_manifest(self) -> None:
        write_text_atomic(self.path / MANIFEST, json.dumps({"command": self.command, "pid": os.getpid(),
                                                            "files": self.files}, indent=1))

    def close(self) -> None:
        """Release the directory (also at exit, or when this object is collected)."""
        _release(self.path)

    def file(self, name: str) -> Path:
        """The path of ``name`` in the directory, recorded in the manifest first (so that a run that
        dies while writing it still owns it)."""
        if not _plain(name):
            raise ValueError(f"output file name {name!r} must be a plain file name")
        if name not in self.files:
            self.files.append(name)
            self._write_manifest()
        return self.path / name

    def discard(self, keep: Iterable[str] = ()) -> list[str]:
        """A failed run: delete the files it wrote (those :meth:`file` recorded) but ``keep``, its
        ``.tmp-*`` files, and the manifest when nothing is kept (else it lists what is); then the
        directory itself when this run created it and it is empty. Other files are left alone.
        Returns the names deleted."""
        kept = [n for n in self.files if n in set(keep) and (self.path / n).is_file()]
        removed = []
        tmp = [e.name for e in self.path.iterdir() if e.name.startswith(f"{TMP_PREFIX}{os.getpid()}-")]
        for name in [*(n for n in self.files if n not in kept), *tmp, *([] if kept else [MANIFEST])]:
            p = self.path / name
            if p.is_file() or p.is_symlink():
                with contextlib.suppress(OSError):
                    p.unlink()
                    removed.append(name)
        self.files = kept
        if kept:
            self._write_manifest()
        elif self.created:
            with contextlib.suppress(OSError):
                self.path.rmdir()  # (only when empty)
        return removed

    @contextlib.contextmanager
    def discarded_on_error(self, keep: Callable[[], Iterable[str]] | None = None) -> Iterator[OutDir]:
        """``with out.discarded_on_error():`` a block that raises leaves nothing of this run in the
        directory (:meth:`discard`), but the files ``keep()`` names (e.g. an online track that holds
        estimates). An interrupt (Ctrl-C) keeps everything written so far."""
        try:
            yield self
        except Exception:
            removed = self.discard(keep() if keep is not None else ())
            if removed:
                log.info("%s: the run failed; removed what it wrote (%s)", self.path, ", ".join(removed))
            raise

    def write_text(self, name: str, text: str) -> Path:
        return write_text_atomic(self.file(name), text)

    def __truediv__(self, name: str) -> Path:
        return self.file(name)

    def __fspath__(self) -> str:
        return str(self.path)

    def __str__(self) -> str:
        return str(self.path)


_LOCKS: dict[str, list[int]] = {}  # real path -> [fd, users in this process]


def _lock_dir(path: Path, flag: str) -> str:
    """Take the directory for this process (``flock`` on the directory itself: nothing is written, and
    the kernel releases it when the process ends, however it ends). A directory another process holds
    is a :class:`GraphnavError` naming the holder (its pid and command, from the manifest)."""
    key = os.path.realpath(path)
    if key in _LOCKS:  # this process already holds it (a command that opens its --out twice)
        held, now = os.fstat(_LOCKS[key][0]), os.stat(path)
        if (held.st_dev, held.st_ino) == (now.st_dev, now.st_ino):
            _LOCKS[key][1] += 1
            return key
        with contextlib.suppress(OSError):  # the directory was removed and made again: lock the new one
            os.close(_LOCKS.pop(key)[0])
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        return key
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        holder = "another process"
        with contextlib.suppress(OSError, ValueError, AttributeError):
            obj = json.loads((path / MANIFEST).read_text(encoding="utf-8"))
            holder = f"process {int(obj['pid'])} ('graphnav {obj['command']}')"
        raise GraphnavError(f"{flag}: the directory is in use by {holder}; wait for it to finish or choose "
                            "another directory", where=str(path)) from None
    _LOCKS[key] = [fd, 1]
    return key


def _release(path: Path) -> None:
    key = os.path.realpath(path)
    entry = _LOCKS.get(key)
    if entry is None:
        return
    entry[1] -= 1
    if entry[1] <= 0:
        del _LOCKS[key]
        with contextlib.suppress(OSError):
            os.close(entry[0])


def _plain(name: str) -> bool:
    return bool(name) and name not in (".", "..") and "/" not in name and "\\" not in name and name != MANIFEST
