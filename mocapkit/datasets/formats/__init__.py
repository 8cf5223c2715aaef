"""File formats: the :class:`Motion` container, one reader/writer module per format, skeleton layouts.

Nothing here imports torch. ``read_motion`` / ``write_motion`` dispatch on the file name:

=================  ===========================================  ==============================
module             format                                       reader / writer
=================  ===========================================  ==============================
``ntu_skeleton``   NTU RGB+D ``.skeleton`` text                 ``read_skeleton`` / ``write_skeleton``
``asf_amc``        Acclaim ASF skeleton + AMC motion (HDM05,    ``read_asf``, ``read_amc`` /
                   CMU), with forward kinematics                ``write_asf``, ``write_amc``
``bvh``            Biovision hierarchy                          ``read_bvh`` / ``write_bvh``
``c3d``            C3D marker files (pure-Python reader)        ``read_c3d`` / ``write_c3d``
``msr_action3d``   MSR Action3D ``aAA_sSS_eEE_skeleton3D.txt``  ``read_msr_skeleton``
``casia_b``        CASIA-B silhouette folders (PNG)             ``list_casia_b``, ``read_sequence``
=================  ===========================================  ==============================

Every reader's file-and-line error derives from :class:`~mocapkit.datasets.formats.errors.MotionFormatError`.
"""
