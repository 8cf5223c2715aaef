"""NTU RGB+D: preparation of ``.skeleton`` folders into a memory-mapped cache (``prepare``,
``cache``), the X-Sub / X-View / X-Set protocols (``splits``) and the Lightning data module
(``datamodule``). The file format itself is :mod:`mocapkit.datasets.formats.ntu_skeleton`."""
