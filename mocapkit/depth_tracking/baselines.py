"""The two baselines of depth tracking that read the sensor's own skeleton instead of the depth (Lou 2012 ch. 3
compares its tracker with what the Kinect SDK reports; Zhou 2014 ch. 5 corrects that skeleton).

- :class:`SensorSkeleton`: the 16 tracked joints of the sequence's ``sensor_joints``, as the vendor SDK reports them.
- :class:`SensorSkeletonGP`: that skeleton corrected by Zhou's GP posture reconstructor (the ``kinect`` task's
  ``gp`` method, ``configs/kinect/method/gp.yaml``), trained on the training performers' (sensor skeleton, ground
  truth) pairs. The reconstructor works in **world** coordinates (y up: its postures are normalised about the
  vertical), so both directions go through the sequence's ``camera_to_world``.

Both follow :mod:`mocapkit.depth_tracking.base`; neither looks at a depth pixel, but both refuse the sequences
:func:`~mocapkit.depth_tracking.base.check_sequence` refuses, so every estimator accepts the same input.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from mocapkit.datasets.formats.depth_images import DepthSequence
from mocapkit.depth_tracking.base import DepthInputError, check_sequence, tracked_joints
from mocapkit.motion.layouts import LANDMARK_NAMES

#: The ``kinect`` registry entry :class:`SensorSkeletonGP` builds its corrector from.
CORRECTOR_METHOD = ("kinect", "gp")


def _label(sequence: DepthSequence) -> str:
    return sequence.source or "depth sequence"


def _sequence_list(sequences, what: str) -> list[DepthSequence]:
    """One sequence or a list of them → a non-empty list; a ValueError naming ``what`` otherwise."""
    if isinstance(sequences, DepthSequence):
        return [sequences]
    sequences = list(sequences)
    if not sequences:
        raise ValueError(f"{what}: no sequences")
    bad = [type(s).__name__ for s in sequences if not isinstance(s, DepthSequence)]
    if bad:
        raise ValueError(f"{what}: expected DepthSequence objects, got a {bad[0]}")
    return sequences


def _check_kinect20(sequence: DepthSequence, name: str) -> np.ndarray:
    """``sequence.<name>`` as float64 ``[T, 20, 3]`` in LANDMARK_NAMES order, or a DepthInputError naming the file
    (check_sequence has checked that it is there, finite and ``[T, J, 3]``)."""
    value = getattr(sequence, name)
    names = tuple(sequence.joint_names)
    if value.shape[1] != len(LANDMARK_NAMES) or (names and names != tuple(LANDMARK_NAMES)):
        raise DepthInputError(
            f"{_label(sequence)}: {name} must be the Kinect-20 skeleton ({len(LANDMARK_NAMES)} joints in "
            f"LANDMARK_NAMES order), got {value.shape[1]} joints"
        )
    return np.asarray(value, dtype=np.float64)


def _sensor_state(sequence: DepthSequence) -> np.ndarray | None:
    """The sensor's tracking states ``[T, 20]`` (0, 1, 2), or None when the sequence has none."""
    state = sequence.sensor_state
    if state is None:
        return None
    state = np.asarray(state)
    if state.shape != (sequence.num_frames, len(LANDMARK_NAMES)) or not np.isin(state, (0, 1, 2)).all():
        raise DepthInputError(
            f"{_label(sequence)}: sensor_state must be [{sequence.num_frames}, {len(LANDMARK_NAMES)}] tracking "
            f"states 0, 1 or 2, got {getattr(state, 'dtype', '')} {list(state.shape)}"
        )
    return state.astype(np.int8)


def _camera_to_world(sequence: DepthSequence, owner: str) -> np.ndarray:
    """The sequence's ``camera_to_world`` ``[4, 4]``, checked to be a finite invertible affine map."""
    matrix = sequence.camera_to_world
    if matrix is None:
        raise DepthInputError(
            f"{_label(sequence)}: {owner} needs the sequence's camera_to_world (its corrector works in world "
            "coordinates, y up), which it does not have"
        )
    matrix = np.asarray(matrix, dtype=np.float64)
    if (
        matrix.shape != (4, 4)
        or not np.isfinite(matrix).all()
        or not np.allclose(matrix[3], (0.0, 0.0, 0.0, 1.0))
        or abs(np.linalg.det(matrix[:3, :3])) < 1e-9
    ):
        raise DepthInputError(
            f"{_label(sequence)}: camera_to_world must be a finite invertible affine 4×4 matrix (last row 0 0 0 1), "
            f"got {matrix.tolist() if matrix.size <= 16 else list(matrix.shape)}"
        )
    return matrix


def _apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The affine ``matrix`` ``[4, 4]`` applied to points ``[..., 3]``."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


class SensorSkeleton(BaseEstimator):
    """The vendor SDK's skeleton: the 16 tracked joints of ``sequence.sensor_joints`` (camera coordinates).

    It learns nothing: :meth:`predict` works before :meth:`fit` and gives the same after it.

    Attributes (after ``fit``): ``n_sequences_`` (the training sequences it was given, unused).
    """

    def fit(self, sequences) -> SensorSkeleton:
        """Nothing to learn; returns self."""
        self.n_sequences_ = len(_sequence_list(sequences, "SensorSkeleton.fit"))
        return self

    def predict(self, sequence: DepthSequence) -> np.ndarray:
        """float32 ``[T, 16, 3]``: the sensor skeleton's tracked joints, camera coordinates (metres)."""
        check_sequence(sequence, needs=("sensor_joints",))
        return tracked_joints(_check_kinect20(sequence, "sensor_joints")).astype(np.float32)


class SensorSkeletonGP(BaseEstimator):
    """The sensor skeleton corrected by Zhou 2014's GP reconstructor (module docstring).

    Args:
        corrector: parameters of :class:`~mocapkit.kinect.reconstruction.KinectPostureReconstructor` that replace
            those of the ``kinect`` task's ``gp`` entry (``configs/kinect/method/gp.yaml``), e.g.
            ``{"n_inducing": 50}``; None: that entry as it is.

    Attributes (after ``fit``): ``corrector_`` (the fitted reconstructor), ``n_sequences_``, ``n_frames_``.

    The reconstructor is built through the method registry (:func:`mocapkit.train.registry.build_method`), not
    imported: the task packages never import each other (docs/extending.md#the-layers).
    """

    def __init__(self, corrector: dict | None = None):
        self.corrector = corrector

    def _build_corrector(self):
        from mocapkit.train.registry import build_method

        model = build_method(*CORRECTOR_METHOD)
        if self.corrector is None:
            return model
        if not isinstance(self.corrector, Mapping):
            raise ValueError(
                f"SensorSkeletonGP: corrector must be a dict of {type(model).__name__} parameters or None, got "
                f"{type(self.corrector).__name__}"
            )
        known = model.get_params(deep=False)
        unknown = [str(k) for k in self.corrector if str(k) not in known]
        if unknown:
            raise ValueError(
                f"SensorSkeletonGP: corrector key {unknown[0]!r} is not a parameter of {type(model).__name__}; its "
                f"parameters: {', '.join(known)}"
            )
        return model.set_params(**{str(k): v for k, v in self.corrector.items()})

    def fit(self, sequences) -> SensorSkeletonGP:
        """Train the GP on the training sequences' (``sensor_joints``, ``joints``) pairs in world coordinates, with
        their ``sensor_state``; a DepthInputError names the file that lacks one of them or ``camera_to_world``."""
        sequences = _sequence_list(sequences, "SensorSkeletonGP.fit")
        sensor, truth, states = [], [], []
        for seq in sequences:
            check_sequence(seq, needs=("joints", "sensor_joints"), what="fit")
            to_world = _camera_to_world(seq, "SensorSkeletonGP.fit")
            sensor.append(_apply(to_world, _check_kinect20(seq, "sensor_joints")))
            truth.append(_apply(to_world, _check_kinect20(seq, "joints")))
            states.append(_sensor_state(seq))
        model = self._build_corrector()
        model.fit(sensor, truth, states)
        self.corrector_ = model
        self.n_sequences_ = len(sequences)
        self.n_frames_ = int(sum(len(s) for s in sensor))
        return self

    def predict(self, sequence: DepthSequence) -> np.ndarray:
        """float32 ``[T, 16, 3]``: the corrected skeleton's tracked joints, camera coordinates (metres)."""
        check_is_fitted(self, "corrector_")
        check_sequence(sequence, needs=("sensor_joints",))
        to_world = _camera_to_world(sequence, "SensorSkeletonGP.predict")
        world = _apply(to_world, _check_kinect20(sequence, "sensor_joints"))
        corrected = self.corrector_.predict(world, state=_sensor_state(sequence))
        return tracked_joints(_apply(np.linalg.inv(to_world), corrected)).astype(np.float32)


__all__ = ["SensorSkeleton", "SensorSkeletonGP"]
