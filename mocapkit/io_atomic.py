"""Atomic, durable file writes: the one helper every writer of checkpoints, caches, indexes and reports uses.

A file is written to a temporary sibling ``<dest>.tmp-<pid>`` *in the destination folder* (so the
final step is a rename within one filesystem, never a copy), flushed and ``fsync``-ed, then
``os.replace``-d onto ``dest``, and the folder is ``fsync``-ed so the rename itself survives a crash.
A process killed at any moment leaves either the previous ``dest`` or the new one, complete; at worst
a stray ``<dest>.tmp-<pid>`` that the next write of the same process id replaces. ``$TMPDIR`` plays
no part.

    atomic_write_text(path, text)             # reports, configs, indexes
    atomic_write_bytes(path, data)
    with atomic_open(path, "wb") as f:        # a stream: torch.save(obj, f), np.save(f, array)
        ...
    with atomic_path(path) as tmp:            # a library that wants a file name: onnx.save(proto, tmp)
        ...

On an exception inside the ``with`` block the temporary file is removed and ``dest`` is left as it was.
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import IO

__all__ = ["atomic_open", "atomic_path", "atomic_write_bytes", "atomic_write_text", "fsync_dir", "temp_path_for"]


def temp_path_for(dest: str | os.PathLike, suffix: str = "") -> Path:
    """The temporary sibling of ``dest`` this process writes: ``<dest>.tmp-<pid><suffix>`` in the same folder
    (``suffix`` for writers that insist on an extension, such as ezc3d's ``.c3d``)."""
    dest = Path(dest)
    return dest.with_name(f"{dest.name}.tmp-{os.getpid()}{suffix}")


def fsync_dir(folder: str | os.PathLike) -> None:
    """``fsync`` a folder so that a rename in it is durable (a no-op where folders cannot be opened)."""
    try:
        fd = os.open(str(folder), os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:  # e.g. Windows
        return
    try:
        os.fsync(fd)
    except OSError:  # some filesystems refuse fsync on folders
        pass
    finally:
        os.close(fd)


def _fsync_file(path: Path) -> None:
    fd = os.open(str(path), os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _commit(tmp: Path, dest: Path) -> None:
    """fsync ``tmp``, give it ``dest``'s permission bits (if ``dest`` exists), rename it onto ``dest``, fsync the folder."""
    _fsync_file(tmp)
    try:
        os.chmod(tmp, stat.S_IMODE(os.stat(dest).st_mode))
    except OSError:  # no previous file (or a filesystem without modes): the umask's default stays
        pass
    os.replace(tmp, dest)
    fsync_dir(dest.parent)


def _check_dest(dest: Path) -> None:
    if dest.is_dir():
        raise IsADirectoryError(f"{dest} is a folder: expected a file name")
    if not dest.parent.is_dir():
        raise FileNotFoundError(f"{dest.parent}: no such folder (to write {dest.name})")


@contextlib.contextmanager
def atomic_path(dest: str | os.PathLike, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``dest`` (ending in ``suffix``); when the block ends without an exception,
    move it onto ``dest``.

    The block must write (and close) the whole file at the yielded path. Raises ``IsADirectoryError`` when
    ``dest`` is a folder and ``FileNotFoundError`` when its folder does not exist (nothing is created).
    """
    dest = Path(dest)
    _check_dest(dest)
    tmp = temp_path_for(dest, suffix)
    try:
        yield tmp
        if not tmp.is_file():
            raise FileNotFoundError(f"{tmp}: nothing was written for {dest}")
        _commit(tmp, dest)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_open(
    dest: str | os.PathLike, mode: str = "wb", encoding: str | None = None, newline: str | None = None
) -> Iterator[IO]:
    """``open(tmp, mode)`` on the temporary sibling of ``dest``; on success flushed, fsynced and renamed onto ``dest``."""
    if mode not in ("w", "wb", "wt"):
        raise ValueError(f"atomic_open: mode must be 'w', 'wt' or 'wb', got {mode!r}")
    if "b" not in mode and encoding is None:
        encoding = "utf-8"
    with atomic_path(dest) as tmp:
        with open(tmp, mode, encoding=encoding, newline=newline) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())


def atomic_write_bytes(dest: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``dest`` atomically and durably; return ``dest``."""
    with atomic_open(dest, "wb") as f:
        f.write(data)
    return Path(dest)


def atomic_write_text(dest: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``dest`` atomically and durably; return ``dest``."""
    with atomic_open(dest, "w", encoding=encoding) as f:
        f.write(text)
    return Path(dest)
