"""The error every motion-file reader raises for a malformed file.

Each format has its own subclass (``SkeletonFormatError``, ``AsfFormatError``,
``AmcFormatError``, ``BvhFormatError``, ``C3DFormatError``, ``MSRFormatError``),
so callers can catch one format or, with :class:`MotionFormatError`, all of them.
"""

from __future__ import annotations

import os


class MotionFormatError(ValueError):
    """A malformed motion file. The message names the file, and the 1-based line and/or frame where known.

    Attributes:
        path: the file.
        line: 1-based line number, or None.
        frame: frame number as the file counts it, or None.
        detail: the message without the location.
    """

    def __init__(self, path: str | os.PathLike, line: int | None, message: str, frame: int | None = None):
        self.path = str(path)
        self.line = line
        self.frame = frame
        self.detail = message
        where = self.path
        if line is not None:
            where += f", line {line}"
        if frame is not None:
            where += f" (frame {frame})" if line is not None else f", frame {frame}"
        super().__init__(f"{where}: {message}")

    def __reduce__(self):  # picklable, so worker processes can send it back
        return (type(self), (self.path, self.line, self.detail, self.frame))
