"""Kinect posture reconstruction (Zhou 2014 ch. 5): the GP reconstructor, its baselines, the learned corrector, ``mocapkit kinect-fix`` and the benchmark."""
