"""Drawing motions: skeleton animations (GIF/MP4) and PNG strips (``render``). Result plots
(confusion matrices, per-view curves) live beside their metrics in :mod:`mocapkit.evaluation`."""
