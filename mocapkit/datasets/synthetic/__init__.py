"""Synthetic stand-ins written in the real formats: NTU ``.skeleton`` (``ntu``), HDM05 ASF/AMC
(``hdm05``) and CASIA-B silhouette folders (``casia_b``), with the forward kinematics they share
(``kinematics``). Each output is a deterministic function of its config and seed."""
