"""HDM05: clip names and the 130 / 65 / 25 class labellings (``classes``, table in ``data/``) and
the cross-actor splits (``splits``). The files are ASF/AMC (:mod:`mocapkit.datasets.formats.asf_amc`)."""
