"""Motion features computed from joint positions: the clip windows and clip features of the
NMF bag-of-words pipeline (``clips``)."""
