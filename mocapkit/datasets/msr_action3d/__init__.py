"""MSR Action3D: the data set (``dataset``), the cross-subject / random-half / AS1-3 protocols
(``splits``) and the Lightning data module (``datamodule``). The file format itself is
:mod:`mocapkit.datasets.formats.msr_action3d`."""
