"""Motion variation synthesis (Zhou 2014 ch. 4): new, natural variants of a motion type from about ten examples.

The contract every synthesiser follows (fit on example clips, sample variants as AMC motions) is in
:mod:`mocapkit.synthesis.base`. The methods, one module each (imported on use: the CVAE needs torch):

- :mod:`~mocapkit.synthesis.slfm`: ``SLFMSynthesizer``, Zhou's SLFM multi-output GPs per joint (eq. 4.2–4.4), with
  :mod:`~mocapkit.synthesis.representation` (exp-map joint features, the root's relative ground-plane motion) and
  :mod:`~mocapkit.synthesis.footskate` (contact cleanup);
- baselines: :mod:`~mocapkit.synthesis.perlin` (``PerlinNoiseSynthesizer``; ``CopyTrainingClips``, the training
  set as a reference row), :mod:`~mocapkit.synthesis.lau` (``LauDBNSynthesizer``, Lau et al. 2009),
  :mod:`~mocapkit.synthesis.cvae` (``CVAESynthesizer``, an autoregressive conditional VAE);
- :mod:`~mocapkit.synthesis.synthesize`: ``mocapkit synthesize``. Metrics: :mod:`mocapkit.synthesis.metrics`;
  the comparison: ``mocapkit compare synthesis_hdm05``.
"""

from mocapkit.synthesis.base import MotionSynthesizer
from mocapkit.synthesis.clips import DofLayout, SynthesisInputError, check_clips, dof_matrix, dof_values

__all__ = ["DofLayout", "MotionSynthesizer", "SynthesisInputError", "check_clips", "dof_matrix", "dof_values"]
