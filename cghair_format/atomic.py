"""Atomic file output, used by every writer (.cgh, strands, USD, PLY, images), and the CLI's early check.

A file is written to a temporary name in its own folder, flushed to disk, renamed over the target and the
folder flushed too, so that a reader, a crash or a full disk leaves either the old file or the whole new
one, never a partial file. A failure (an exception, ``KeyboardInterrupt`` included) removes the temporary
file. New files get the mode ``open()`` gives (0666 less the umask), as any other tool's files do.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

from .errors import OutputError


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside ``path``, with the same extension (for writers that choose the format by
    it, such as usd-core and Pillow), to write in full; on success it replaces ``path``."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp{path.suffix}")
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_folder(path.parent)


@contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "wb", **kwargs) -> Iterator[BinaryIO]:
    """``open(path, mode)`` (a writing mode) into a temporary file that replaces ``path`` once closed."""
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as f:
        yield f


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    with atomic_open(path) as f:
        f.write(data)


def write_text(path: str | os.PathLike, text: str) -> None:
    with atomic_open(path, "w", encoding="utf-8") as f:
        f.write(text)


def _fsync_folder(folder: Path) -> None:
    """Flush the folder's entry of the renamed file (a no-op where folders cannot be opened, as on Windows)."""
    try:
        fd = os.open(folder if str(folder) else ".", os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def check_writable(path: str | os.PathLike, folder: bool = False, make_parents: bool = False) -> None:
    """Raise :class:`OutputError` when ``path`` (a file, or with ``folder`` a folder) cannot be written:
    what the CLI checks before its long work. A folder output, and with ``make_parents`` a file's
    folder, is made as needed, so only its nearest existing parent must be a writable folder."""
    path = Path(path)
    if path.exists() and path.is_dir() != folder:
        raise OutputError(f"cannot write {path}: it is {'not ' if folder else ''}a folder")
    parent = path if folder else path.parent
    while not parent.exists() and (folder or make_parents) and parent != parent.parent:
        parent = parent.parent
    parent = parent if str(parent) else Path(".")
    if not parent.exists():
        raise OutputError(f"cannot write {path}: the folder {parent} does not exist")
    if not parent.is_dir():
        raise OutputError(f"cannot write {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write {path}: the folder {parent} is not writable")
