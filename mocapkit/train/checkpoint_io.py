"""Lightning checkpoint I/O that cannot leave a damaged ``last.ckpt`` behind, and never unpickles code.

:class:`AtomicCheckpointIO` writes every checkpoint with :func:`mocapkit.io_atomic.atomic_open`: to
``<dest>.tmp-<pid>`` in the destination folder, flushed and fsynced, then ``os.replace``-d onto
``<dest>`` and the folder fsynced. A kill at any moment leaves the previous checkpoint intact, whatever
``$TMPDIR`` is (Lightning's default goes through an fsspec transaction in ``$TMPDIR``, which becomes a
copy in place when that is another filesystem). Loading (``resume=``) always uses ``weights_only=True``.
:func:`mocapkit.train.training.train` passes it to the trainer as a plugin.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from lightning.pytorch.plugins.io import TorchCheckpointIO

from mocapkit.io_atomic import atomic_open


def _is_local(path) -> bool:
    return "://" not in str(path) or str(path).startswith("file://")


class AtomicCheckpointIO(TorchCheckpointIO):
    """``TorchCheckpointIO`` with atomic, durable local saves and ``weights_only=True`` loads."""

    def save_checkpoint(self, checkpoint: dict[str, Any], path, storage_options: Any | None = None) -> None:
        if storage_options is not None or not _is_local(path):
            return super().save_checkpoint(checkpoint, path, storage_options)
        path = Path(str(path).removeprefix("file://"))
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(path, "wb") as f:
            torch.save(checkpoint, f)

    def load_checkpoint(self, path, map_location=lambda storage, loc: storage, weights_only: bool | None = None):
        return super().load_checkpoint(path, map_location=map_location, weights_only=True)
