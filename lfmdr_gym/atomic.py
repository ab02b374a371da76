"""Atomic file writes: a reader (or a crash) never sees a half-written file.

Every file lfmdr writes for a user — histories, results, tables, maps, figures — goes through
:func:`atomic_write`: the content is written to a temporary file in the same folder, flushed
and fsync-ed, then renamed over the target in one step (``os.replace`` is atomic on POSIX and
Windows). On any error the temporary file is removed and the old target, if any, is untouched.
The files of one output (a map's CSV, YAML, JSON, figure and scores) go through
:func:`atomic_file_set`: all of them are replaced, or none.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", **open_kwargs: Any) -> Iterator[IO]:
    """Open a temporary file to write ``path``'s new content; it replaces ``path`` on success.

    ``mode`` is ``"w"`` (text, UTF-8 and ``newline=""`` unless given) or ``"wb"``.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if mode == "w":
        open_kwargs.setdefault("encoding", "utf-8")
        open_kwargs.setdefault("newline", "")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp's 0600 would make the user's file private
        with os.fdopen(fd, mode, **open_kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (UTF-8, newlines as given)."""
    with atomic_write(path, "w") as fh:
        fh.write(text)
    return Path(path)


def atomic_savefig(fig: Any, path: str | os.PathLike, **savefig_kwargs: Any) -> Path:
    """Save a matplotlib figure atomically; the format follows ``path``'s suffix."""
    path = Path(path)
    savefig_kwargs.setdefault("format", path.suffix.lstrip(".") or "png")
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, **savefig_kwargs)
    return path


class AtomicFileSet:
    """The files of one output set, written to temporaries in ``folder`` (see
    :func:`atomic_file_set`). :meth:`path` gives the temporary to write a file's content to."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self._temps: dict[str, Path] = {}

    def path(self, name: str) -> Path:
        """The temporary file that becomes ``folder/name`` when the set is committed (its
        suffix is ``name``'s, so writers that choose a format by suffix choose the right one)."""
        if name in self._temps:
            return self._temps[name]
        if Path(name).name != name or name in ("", ".", ".."):
            raise ValueError(f"a file of the set must be a plain file name, got {name!r}")
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=f".tmp{Path(name).suffix}",
                                   dir=self.folder)
        os.fchmod(fd, 0o666 & ~_umask())
        os.close(fd)
        self._temps[name] = Path(tmp)
        return Path(tmp)

    def write_text(self, name: str, text: str) -> None:
        """``folder/name``'s content (UTF-8, newlines as given)."""
        self.path(name).write_text(text, encoding="utf-8", newline="")

    def write_bytes(self, name: str, data: bytes) -> None:
        self.path(name).write_bytes(data)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._temps)

    def _discard(self) -> None:
        for tmp in self._temps.values():
            tmp.unlink(missing_ok=True)

    def _commit(self) -> None:
        """fsync every temporary, keep a backup (hard link, else a copy) of every file it
        replaces, then rename them all; a failure while renaming puts the backups back and
        removes what was new, so the folder is as it was."""
        for tmp in self._temps.values():
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        backups: dict[Path, Path | None] = {}
        done: list[Path] = []
        try:
            for name in self._temps:
                target = self.folder / name
                backups[target] = _backup(target) if target.exists() else None
            for name, tmp in self._temps.items():
                os.replace(tmp, self.folder / name)
                done.append(self.folder / name)
        except BaseException:
            for target in done:
                old = backups.get(target)
                if old is None:
                    target.unlink(missing_ok=True)
                else:
                    os.replace(old, target)
            raise
        finally:
            for old in backups.values():
                if old is not None:
                    old.unlink(missing_ok=True)


def _backup(target: Path) -> Path:
    """A hidden copy of ``target`` beside it (a hard link where the file system has them: no data
    copied)."""
    import shutil

    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".bak", dir=target.parent)
    os.close(fd)
    backup = Path(name)
    backup.unlink()
    try:
        os.link(target, backup)
    except OSError:  # no hard links here (some network or FAT file systems): copy it
        shutil.copy2(target, backup)
    return backup


@contextmanager
def atomic_file_set(folder: str | os.PathLike) -> Iterator[AtomicFileSet]:
    """Write several files into ``folder`` as one set: all of them or none.

    Inside the ``with`` block each file is written to a temporary in ``folder`` (``files.path(name)``
    or ``files.write_text(name, text)``); when the block ends without error they are fsync-ed and
    renamed over their targets. On any error, in the block or while renaming, the temporaries are
    removed and the files already renamed are put back, so ``folder`` is left exactly as it was
    (a file that was not there is not there, and a folder this call created is removed again).
    A reader may see some new files beside some old ones during the renames (no file system
    renames several files in one step), never a half-written file.
    """
    folder = Path(folder)
    created = [p for p in (folder, *folder.parents) if not p.exists()]
    folder.mkdir(parents=True, exist_ok=True)
    files = AtomicFileSet(folder)
    try:
        yield files
        files._commit()
    except BaseException:
        files._discard()
        for made in created:  # deepest first; one that is not empty now is someone else's
            try:
                made.rmdir()
            except OSError:
                break
        raise
