"""A Lightning callback that prints one line per epoch, for logs and runs without a progress bar."""

from __future__ import annotations

import time

import lightning as L


class EpochSummary(L.Callback):
    """Prints ``epoch 3/30  train/loss 1.234  train/acc 0.456  val/acc 0.400  12.3 s`` after each epoch."""

    def on_train_epoch_start(self, trainer: L.Trainer, module: L.LightningModule) -> None:
        self._start = time.time()

    def on_train_epoch_end(self, trainer: L.Trainer, module: L.LightningModule) -> None:
        if not trainer.is_global_zero:  # one line per epoch, not one per process
            return
        # Lightning 2 calls this after the epoch's validation, so both sets of metrics are here
        metrics = trainer.callback_metrics
        shown = "  ".join(
            f"{k} {float(metrics[k]):.4f}"
            for k in ("train/loss_epoch", "train/acc", "val/loss", "val/acc", "val/mje_cm")
            if k in metrics
        )
        print(
            f"epoch {trainer.current_epoch + 1}/{trainer.max_epochs}  {shown}  {time.time() - self._start:.1f} s",
            flush=True,
        )
