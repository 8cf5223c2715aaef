"""CASIA-B gait: Gait Energy Images (``gei``), ``prepare casia-b`` into a GEI cache (``prepare``,
``cache``), the closed-set and cross-subject protocols (``splits``) and the Lightning data module
(``datamodule``). The silhouette folders are read by :mod:`mocapkit.datasets.formats.casia_b`."""
