"""Opening motion files safely: regular files only, and a cap on what a whole-file read may take.

Every reader in :mod:`mocapkit.datasets.formats` reads its file through :func:`read_file_bytes`
(or checks it with :func:`regular_file_size` first), so that

- special files are refused *by name* before they are opened: a directory, a FIFO (opening
  one blocks forever), a character device such as ``/dev/zero`` (reading one never ends and
  raises ``MemoryError``), a socket. Symbolic links are followed and the target is checked;
- a whole-file read never takes more than :data:`MAX_FILE_BYTES` (1 GiB by default,
  ``$MOCAPKIT_MAX_FILE_BYTES`` overrides it). The largest real motion files are tens of MB
  (an NTU ``.skeleton`` is at most ~1 MB, a long CMU AMC a few MB), so a bigger file is
  refused with its size rather than read.

The error raised is the reader's own format error (``error(path, message)``), so callers that
catch :class:`~mocapkit.datasets.formats.errors.MotionFormatError` see these too.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from pathlib import Path

#: The most bytes a reader reads from one file (1 GiB; ``$MOCAPKIT_MAX_FILE_BYTES`` overrides it).
MAX_FILE_BYTES = int(os.environ.get("MOCAPKIT_MAX_FILE_BYTES", str(1 << 30)))

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def regular_file_size(
    path: str | os.PathLike, error: Callable[[Path, str], Exception], max_bytes: int | None = None
) -> int:
    """The size of ``path`` after checking it is a regular file (links followed) of at most ``max_bytes``.

    Raises ``error(path, message)`` for a missing or unreadable file, a special file
    (naming what it is, and the link target) or a file above the cap.
    """
    path = Path(path)
    limit = MAX_FILE_BYTES if max_bytes is None else max_bytes
    try:
        st = os.stat(path)  # follows symbolic links
    except OSError as exc:
        raise error(path, f"cannot read file ({exc.strerror or exc})") from exc
    if not stat.S_ISREG(st.st_mode):
        kind = next((what for test, what in _KINDS if test(st.st_mode)), "not a regular file")
        target = ""
        if os.path.islink(path):
            target = f" (a link to {os.path.realpath(path)})"
        raise error(path, f"refusing to read {kind}{target}: motion files must be regular files")
    if st.st_size > limit:
        raise error(
            path,
            f"file is {st.st_size} bytes, more than the {limit}-byte limit for one motion file "
            "(MOCAPKIT_MAX_FILE_BYTES)",
        )
    return int(st.st_size)


def read_file_bytes(
    path: str | os.PathLike, error: Callable[[Path, str], Exception], max_bytes: int | None = None
) -> bytes:
    """The whole content of a regular file of at most ``max_bytes`` (see :func:`regular_file_size`).

    Reads at most the checked size plus one byte, so a file that grows meanwhile (or a
    file system that misreports sizes) cannot make the read unbounded.
    """
    path = Path(path)
    size = regular_file_size(path, error, max_bytes)
    try:
        with open(path, "rb") as fh:
            if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):  # replaced between stat and open
                raise error(path, "refusing to read a file that is not a regular file")
            data = fh.read(max(size, 0) + 1)
    except OSError as exc:
        raise error(path, f"cannot read file ({exc.strerror or exc})") from exc
    if len(data) > size:
        raise error(path, f"file grew beyond its {size} bytes while being read")
    return data
