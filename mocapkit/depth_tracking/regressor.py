"""The learned baseline of the depth-tracking task: a CNN regressing the 16 tracked joints from each depth frame
alone (no tracking, no skeleton model), trained on the training performers' rendered depth and ground-truth joints.

**Preprocessing** (:func:`depth_crop`, the same in training, :meth:`DepthJointRegressor.predict` and the ONNX
twin :class:`OnnxDepthJointRegressor`):

1. Foreground = the pixels with a depth measurement (depth > 0). The synthetic sensor writes 0 for the background;
   a real recording needs the person segmented first (the SDK's body-index mask, or a depth range around the
   person), with every other pixel set to 0, or the floor and walls count as body.
2. Centre = the per-axis median of the foreground pixels un-projected to camera coordinates (metres)
   (:func:`foreground_centre`).
3. Crop = a square of fixed *metric* side (``crop_extent_m``, 2.2 m: a standing adult with raised arms) in the
   plane z = centre depth, around the centre, sampled on an S × S grid (``crop_size``) by nearest pixel, so no
   pixel mixes the depths of two surfaces. Values: (depth − centre depth) / ``depth_scale_m``, clipped to
   [−1, 1]; background (and the outside of the image) :data:`BACKGROUND` (1: "far behind").

Because the crop is metric and the targets are joints relative to the centre in metres, the network does not see
the camera: a model trained on 320 × 240 Kinect v1 renders predicts on 640 × 576 Azure Kinect images as well
(the crop is only sampled more finely). :meth:`~DepthJointRegressor.predict` adds the centre back.

**Training** (:class:`~mocapkit.depth_tracking.module.DepthPoseModule`, ``steps`` Adam steps, seeded by
``random_state``): every frame of every training sequence, shuffled; with augmentation each sample's crop centre
is shifted in the image plane by up to ``shift_m`` per axis (the target moves with it, so the network learns not to
trust the median centre blindly) and Gaussian noise of ``depth_noise_m`` is added to its foreground depths. The
output layer starts at the training frames' mean pose, so the network learns the deviations from it. The Lightning
``Trainer`` is :func:`~mocapkit.train.training.build_estimator_trainer`'s with the ``trainer`` parameter on top.

**Export**: :meth:`DepthJointRegressor.export_onnx` writes the network alone (input ``crops`` ``[N, 1, S, S]``,
output ``joints`` ``[N, 16, 3]`` metres from the centre; the preprocessing stays in numpy) with the crop parameters
in its metadata, checked against PyTorch with onnxruntime on real crops; :class:`OnnxDepthJointRegressor` predicts
from that file (no PyTorch).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from mocapkit.datasets.formats.depth_images import CameraIntrinsics, DepthSequence
from mocapkit.depth_tracking.base import TRACKED_JOINTS, DepthInputError, check_sequence, tracked_joints
from mocapkit.motion.layouts import LANDMARK_NAMES

MODEL_FORMAT = "mocapkit-depth-regressor-1"
"""The ``format`` of a saved regressor (:meth:`DepthJointRegressor.save`) and of its ONNX export's metadata."""
#: ONNX metadata key holding the crop parameters (JSON) :class:`OnnxDepthJointRegressor` reads.
ONNX_META_KEY = "mocapkit_depth_regressor"
#: Crop value of background pixels and of the outside of the image (foreground values are clipped to [−1, 1]).
BACKGROUND = 1.0
#: Frames per network call in ``predict`` (bounds the memory of long sequences).
PREDICT_BATCH = 256
#: Training crops kept in the fitted estimator (evenly spaced over the frames) for the ONNX parity check.
EXAMPLE_CROPS = 8


# ---------------------------------------------------------------------------------------------------- preprocessing
def foreground_centre(depth_mm: np.ndarray, intrinsics: CameraIntrinsics, label: str = "depth image") -> np.ndarray:
    """The 3-D centre of a frame's foreground: float64 ``[3]`` camera coordinates (metres), the per-axis median of
    the pixels with depth > 0 (``depth_mm`` uint16 ``[H, W]``) un-projected. A DepthInputError names ``label`` when
    no pixel has a depth."""
    v, u = np.nonzero(depth_mm)
    if len(v) == 0:
        raise DepthInputError(f"{label}: no foreground pixel (every depth is 0), nothing to crop")
    z = depth_mm[v, u].astype(np.float64) / 1000.0
    x = (u - intrinsics.cx) * z / intrinsics.fx
    y = (v - intrinsics.cy) * z / intrinsics.fy
    return np.array([np.median(x), np.median(y), np.median(z)])


def depth_crop(
    depth_mm: np.ndarray,
    intrinsics: CameraIntrinsics,
    centre: np.ndarray,
    size: int,
    extent_m: float,
    depth_scale_m: float,
) -> np.ndarray:
    """The normalised crop of one frame (module docstring): float32 ``[size, size]``.

    Args:
        depth_mm: uint16 ``[H, W]`` millimetres, 0 = background.
        intrinsics: the camera of ``depth_mm``.
        centre: ``[3]`` camera coordinates (metres) of the crop centre, z > 0.
        size: S, crop pixels per side.
        extent_m: the crop's side in metres, in the plane z = ``centre[2]``.
        depth_scale_m: metres of depth that map to 1.
    """
    x, y, z = (float(c) for c in centre)
    offsets = ((np.arange(size) + 0.5) / size - 0.5) * extent_m  # metric grid, the same for every camera
    u = np.rint(intrinsics.fx * (x + offsets) / z + intrinsics.cx).astype(np.int64)
    v = np.rint(intrinsics.fy * (y + offsets) / z + intrinsics.cy).astype(np.int64)
    cols = (u >= 0) & (u < depth_mm.shape[1])
    rows = (v >= 0) & (v < depth_mm.shape[0])
    sampled = np.zeros((size, size), dtype=np.uint16)  # outside the image: no measurement
    sampled[np.ix_(rows, cols)] = depth_mm[np.ix_(v[rows], u[cols])]  # nearest pixel: no mixed depths
    foreground = sampled > 0
    crop = np.full((size, size), BACKGROUND, dtype=np.float32)
    crop[foreground] = np.clip((sampled[foreground] / 1000.0 - z) / depth_scale_m, -1.0, 1.0)
    return crop


def depth_crops(
    sequence: DepthSequence, size: int, extent_m: float, depth_scale_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Every frame of ``sequence`` preprocessed: crops float32 ``[T, 1, size, size]`` and their centres float64
    ``[T, 3]`` (camera coordinates, metres). A DepthInputError names the file and the frame without foreground."""
    label = sequence.source or "depth sequence"
    T = sequence.num_frames
    crops = np.empty((T, 1, size, size), dtype=np.float32)
    centres = np.empty((T, 3), dtype=np.float64)
    for t in range(T):
        centres[t] = foreground_centre(sequence.depth_mm[t], sequence.intrinsics, f"{label}: frame {t}")
        crops[t, 0] = depth_crop(sequence.depth_mm[t], sequence.intrinsics, centres[t], size, extent_m, depth_scale_m)
    return crops, centres


def _sequence_list(sequences, what: str) -> list[DepthSequence]:
    if isinstance(sequences, DepthSequence):
        return [sequences]
    sequences = list(sequences) if isinstance(sequences, (list, tuple)) else None
    if not sequences or not all(isinstance(s, DepthSequence) for s in sequences):
        raise ValueError(f"{what} needs a DepthSequence or a non-empty list of them")
    return sequences


def _check_number(owner: str, name: str, value, integer: bool = False, low: float = 0.0, strict: bool = False) -> None:
    """``value`` is a finite number (an integer with ``integer``) ≥ ``low`` (> ``low`` with ``strict``)."""
    ok = isinstance(value, (int, np.integer)) if integer else isinstance(value, (int, float, np.number))
    if isinstance(value, bool) or not ok or not np.isfinite(float(value)) or value < low or (strict and value == low):
        kind = "an integer" if integer else "a finite number"
        raise ValueError(f"{owner}: {name}={value!r} must be {kind} {'>' if strict else '≥'} {low:g}")


# ---------------------------------------------------------------------------------------------------- estimator
class _CropPredictor:
    """``predict`` of both regressors: the sequence check, the crops, ``_run`` on batches, the centres added back."""

    _fitted = ""

    def _crop_params(self) -> tuple[int, float, float]:
        raise NotImplementedError

    def _run(self, crops: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def predict(self, sequence: DepthSequence) -> np.ndarray:
        """float32 ``[T, 16, 3]``: the :data:`~mocapkit.depth_tracking.base.TRACKED_JOINTS` in every frame, camera
        coordinates (metres). A DepthInputError names the file and the frame it cannot work on."""
        check_is_fitted(self, self._fitted)
        if not isinstance(sequence, DepthSequence):
            raise ValueError(f"predict needs a DepthSequence, got {type(sequence).__name__}")
        check_sequence(sequence, what="predict")
        crops, centres = depth_crops(sequence, *self._crop_params())
        relative = np.concatenate(
            [self._run(crops[s : s + PREDICT_BATCH]) for s in range(0, len(crops), PREDICT_BATCH)]
        )
        return (relative + centres[:, None, :]).astype(np.float32)


class DepthJointRegressor(_CropPredictor, BaseEstimator):
    """A CNN from one depth frame to the 16 tracked joints (module docstring).

    Args:
        crop_size: S, the crop's pixels per side (the network's input ``[1, S, S]``).
        crop_extent_m: the crop's side in metres at the centre's depth.
        depth_scale_m: metres of depth (from the centre's) that map to 1 in the crop.
        network: keyword arguments of :func:`~mocapkit.models.depth_pose_cnn.depth_pose_cnn` other than ``joints``
            and ``input_size`` (``{"width": 32}``, ...); None: its defaults.
        steps, batch_size, lr: Adam steps, crops per step, learning rate.
        loss: ``"l1"`` (per-coordinate absolute error, metres) or ``"mse"``.
        shift_m: training augmentation: each crop's centre moves by up to this many metres along x and along y
            (uniform; 0 off).
        depth_noise_m: training augmentation: σ (metres) of Gaussian noise on the crop's foreground depths (0 off).
        random_state: seeds the initialisation, the batches and the augmentation.
        trainer: Lightning ``Trainer`` arguments over ``configs/trainer/default.yaml`` and the estimator's own
            (``max_steps=steps``, no logger, no checkpoint, no progress bar), e.g. ``{"accelerator": "gpu"}`` or
            ``{"enable_progress_bar": True}``; None: those defaults.

    Attributes (after ``fit``): ``module_`` (the trained :class:`~mocapkit.depth_tracking.module.DepthPoseModule`,
    eval mode, on the CPU), ``mean_pose_`` (float32 ``[16, 3]``, the training joints' mean relative to the crop
    centre, metres), ``example_crops_`` (float32 ``[8, 1, S, S]`` training crops, for the ONNX check),
    ``n_frames_``, ``loss_curve_`` (float64 ``[steps]``), ``train_seconds_``. :meth:`save` / :meth:`load` write
    and read one file (the ``trainer`` parameter is not saved: it says where to train, not what was learned).
    """

    trains_network = True  # fit trains a network: "learned" in the method registry
    _fitted = "module_"

    def __init__(
        self,
        crop_size: int = 96,
        crop_extent_m: float = 2.2,
        depth_scale_m: float = 1.0,
        network: dict | None = None,
        steps: int = 1000,
        batch_size: int = 32,
        lr: float = 1e-3,
        loss: str = "l1",
        shift_m: float = 0.1,
        depth_noise_m: float = 0.01,
        random_state: int | None = 0,
        trainer: dict | None = None,
    ):
        self.crop_size = crop_size
        self.crop_extent_m = crop_extent_m
        self.depth_scale_m = depth_scale_m
        self.network = network
        self.steps = steps
        self.batch_size = batch_size
        self.lr = lr
        self.loss = loss
        self.shift_m = shift_m
        self.depth_noise_m = depth_noise_m
        self.random_state = random_state
        self.trainer = trainer

    # ------------------------------------------------------------------ parameters
    def _check_params(self) -> None:
        owner = "DepthJointRegressor"
        _check_number(owner, "crop_size", self.crop_size, integer=True, low=8)
        for name in ("steps", "batch_size"):
            _check_number(owner, name, getattr(self, name), integer=True, low=1)
        for name in ("crop_extent_m", "depth_scale_m", "lr"):
            _check_number(owner, name, getattr(self, name), strict=True)
        for name in ("shift_m", "depth_noise_m"):
            _check_number(owner, name, getattr(self, name))
        if self.loss not in ("l1", "mse"):
            raise ValueError(f"{owner}: loss must be 'l1' or 'mse', got {self.loss!r}")
        if self.network is not None and not isinstance(self.network, Mapping):
            raise ValueError(
                f"{owner}: network must be a dict of depth_pose_cnn arguments or None, got {type(self.network).__name__}"
            )
        fixed = sorted({"joints", "input_size"} & set(self.network or {}))
        if fixed:
            raise ValueError(f"{owner}: network must not set {fixed}: the regressor sets them (16 joints, crop_size)")
        from mocapkit.train.training import check_trainer_parameter

        check_trainer_parameter(self.trainer, owner)

    def _crop_params(self) -> tuple[int, float, float]:
        return int(self.crop_size), float(self.crop_extent_m), float(self.depth_scale_m)

    def _module(self):
        """A fresh :class:`~mocapkit.depth_tracking.module.DepthPoseModule` of this regressor's network."""
        from mocapkit.depth_tracking.module import DepthPoseModule

        network = {str(k): v for k, v in dict(self.network or {}).items()}
        network.update(joints=len(TRACKED_JOINTS), input_size=int(self.crop_size))
        return DepthPoseModule(network=network, lr=float(self.lr), loss=str(self.loss))

    # ------------------------------------------------------------------ fit
    def fit(self, sequences) -> DepthJointRegressor:
        """Train on the training performers' sequences (a list of DepthSequence, or one), each with ground-truth
        Kinect-20 ``joints`` in camera coordinates. A DepthInputError names the file (and frame) it cannot use."""
        import lightning as L
        import torch

        from mocapkit.train.training import build_estimator_trainer

        self._check_params()
        sequences = _sequence_list(sequences, "DepthJointRegressor.fit")
        for seq in sequences:
            check_sequence(seq, needs=("joints",), what="fit")
            if seq.joints.shape[1] != len(LANDMARK_NAMES) or (
                seq.joint_names and tuple(seq.joint_names) != tuple(LANDMARK_NAMES)
            ):
                raise DepthInputError(
                    f"{seq.source or 'depth sequence'}: fit needs Kinect-20 joints ({len(LANDMARK_NAMES)}, in "
                    f"LANDMARK_NAMES order), got {seq.joints.shape[1]} joints"
                )
        size, extent, scale = self._crop_params()
        dataset = _CropDataset(
            sequences,
            size,
            extent,
            scale,
            float(self.shift_m),
            float(self.depth_noise_m),
            0 if self.random_state is None else int(self.random_state),
        )
        self.n_frames_ = len(dataset)
        self.mean_pose_ = dataset.targets.mean(axis=0).astype(np.float32)
        picks = np.linspace(0, len(dataset) - 1, min(EXAMPLE_CROPS, len(dataset))).round().astype(int)
        self.example_crops_ = np.stack([dataset.crop(int(i), np.zeros(2), None) for i in picks])[:, None]

        L.seed_everything(0 if self.random_state is None else int(self.random_state), workers=False, verbose=False)
        module = self._module()
        module.model.start_at(torch.from_numpy(self.mean_pose_))
        curve: list[float] = []

        class _Record(L.Callback):
            def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx):
                curve.append(float(outputs["loss"]) if isinstance(outputs, dict) else float(outputs))

        loader = torch.utils.data.DataLoader(
            dataset,
            batch_size=int(self.batch_size),
            shuffle=True,
            drop_last=len(dataset) > int(self.batch_size),  # every step a full batch (steady BatchNorm statistics)
        )
        trainer = build_estimator_trainer(self.steps, self.trainer, callbacks=[_Record()])
        start = time.perf_counter()
        trainer.fit(module, train_dataloaders=loader)
        self.train_seconds_ = time.perf_counter() - start
        self.loss_curve_ = np.asarray(curve, dtype=np.float64)
        self.module_ = module.cpu().eval()
        return self

    def _run(self, crops: np.ndarray) -> np.ndarray:
        import torch

        with torch.inference_mode():
            return self.module_(torch.from_numpy(np.ascontiguousarray(crops))).numpy()

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike) -> Path:
        """Write the fitted regressor as one ``torch.save`` file of plain values and tensors (parameters, network
        weights, mean pose, example crops; loadable with ``weights_only=True``), atomically; parent folders are
        created."""
        import torch

        from mocapkit.io_atomic import atomic_open

        check_is_fitted(self, "module_")
        params = {k: v for k, v in self.get_params(deep=False).items() if k != "trainer"}
        params["network"] = None if self.network is None else {str(k): v for k, v in dict(self.network).items()}
        state = {
            "format": MODEL_FORMAT,
            "params": params,
            "n_frames": int(self.n_frames_),
            "train_seconds": float(self.train_seconds_),
            "loss_curve": [float(v) for v in self.loss_curve_],
            "mean_pose": torch.from_numpy(np.asarray(self.mean_pose_, dtype=np.float32)),
            "example_crops": torch.from_numpy(np.asarray(self.example_crops_, dtype=np.float32)),
            "state_dict": {k: v.detach().clone() for k, v in self.module_.model.state_dict().items()},
        }
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(path, "wb") as f:
            torch.save(state, f)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> DepthJointRegressor:
        """A regressor written by :meth:`save` (read with ``weights_only=True``); a ValueError names the file when
        it is not one."""
        import torch

        path = Path(path)
        try:
            state = torch.load(path, map_location="cpu", weights_only=True)
            if not isinstance(state, dict) or state.get("format") != MODEL_FORMAT:
                raise ValueError(
                    f"format {state.get('format') if isinstance(state, dict) else None!r}, expected {MODEL_FORMAT!r}"
                )
            model = cls(**state["params"])
            model._check_params()
            module = model._module()
            module.model.load_state_dict(state["state_dict"])
        except Exception as exc:
            raise ValueError(
                f"{path}: not a depth joint regressor written by DepthJointRegressor.save ({exc})"
            ) from exc
        model.module_ = module.eval()
        model.n_frames_, model.train_seconds_ = int(state["n_frames"]), float(state["train_seconds"])
        model.loss_curve_ = np.asarray(state["loss_curve"], dtype=np.float64)
        model.mean_pose_ = state["mean_pose"].numpy()
        model.example_crops_ = state["example_crops"].numpy()
        return model

    # ------------------------------------------------------------------ export
    def export_onnx(
        self,
        path: str | os.PathLike,
        opset: int | None = None,
        atol: float = 1e-4,
        rtol: float = 1e-3,
        sequence: DepthSequence | None = None,
    ) -> dict:
        """Write the network as ONNX (input ``crops`` float32 ``[N, 1, S, S]``, N dynamic; output ``joints``
        float32 ``[N, 16, 3]`` metres from the crop centre) with the crop parameters in the metadata
        (:data:`ONNX_META_KEY`), and check onnxruntime against PyTorch on real crops: the training crops kept in
        ``example_crops_`` (or every frame of ``sequence``), batched differently from the traced batch of 2.

        Args:
            opset: ONNX opset (None: :data:`~mocapkit.deploy.export.DEFAULT_OPSET`, that of every dynamo export).
            atol, rtol: the parity tolerance, metres.

        Returns:
            ``{"onnx", "opset", "traced_shape", "checked_shape", "checks", "max_abs_diff", "atol", "rtol"}``.

        Raises:
            ParityError: onnxruntime differs from PyTorch beyond ``atol + rtol · |reference|``.
        """
        import warnings

        import torch

        from mocapkit.deploy.export import DEFAULT_OPSET, ParityError, save_checked_onnx
        from mocapkit.deploy.runtime import cpu_session

        check_is_fitted(self, "module_")
        opset = DEFAULT_OPSET if opset is None else int(opset)
        size, extent, scale = self._crop_params()
        if sequence is not None:
            check_sequence(sequence, what="export_onnx")
            real = depth_crops(sequence, size, extent, scale)[0]
        else:
            real = np.asarray(self.example_crops_, dtype=np.float32)
        out = Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        model = self.module_.model.eval().cpu()
        trace = torch.from_numpy(np.ascontiguousarray(np.resize(real, (2, 1, size, size))))
        batch = torch.export.Dim("batch", min=1, max=65536)
        with warnings.catch_warnings(), torch.no_grad():
            warnings.simplefilter("ignore")
            # optimize=False as the other exports: onnxscript's optimiser is skipped, the plain graph is correct
            proto = torch.onnx.export(
                model,
                (trace,),
                None,
                input_names=["crops"],
                output_names=["joints"],
                dynamic_shapes={"crops": {0: batch}},
                dynamo=True,
                opset_version=opset,
                optimize=False,
                verbose=False,
            ).model_proto
        meta = {
            ONNX_META_KEY: json.dumps(
                {
                    "format": MODEL_FORMAT,
                    "crop_size": size,
                    "crop_extent_m": extent,
                    "depth_scale_m": scale,
                    "background": BACKGROUND,
                    "joint_names": list(TRACKED_JOINTS),
                }
            ),
            "producer": "mocapkit",
            "input": f"crops float32 [batch, 1, {size}, {size}]: (depth - centre depth) / {scale} m, background "
            f"{BACKGROUND} (mocapkit.depth_tracking.regressor.depth_crop)",
            "output": f"joints float32 [batch, {len(TRACKED_JOINTS)}, 3] metres from the crop centre",
        }
        save_checked_onnx(proto, meta, out)
        session = cpu_session(out)
        checks = []
        for crops in (real, real[:1]):
            with torch.inference_mode():
                reference = model(torch.from_numpy(np.ascontiguousarray(crops))).numpy()
            result = session.run(["joints"], {"crops": np.ascontiguousarray(crops)})[0]
            diff = float(np.abs(result - reference).max())
            checks.append(
                {"shape": list(crops.shape), "max_abs_diff": diff, "max_abs_value": float(np.abs(reference).max())}
            )
            if result.shape != reference.shape or not np.allclose(result, reference, atol=atol, rtol=rtol):
                raise ParityError(
                    f"{out}: onnxruntime differs from PyTorch on crops {list(crops.shape)}: max |diff| = "
                    f"{diff:.3g} m > atol {atol} + rtol {rtol}·|ref|"
                )
        return {
            "onnx": str(out),
            "opset": opset,
            "traced_shape": list(trace.shape),
            "checked_shape": checks[0]["shape"],
            "checks": checks,
            "max_abs_diff": max(c["max_abs_diff"] for c in checks),
            "atol": atol,
            "rtol": rtol,
        }


class OnnxDepthJointRegressor(_CropPredictor, BaseEstimator):
    """A regressor exported by :meth:`DepthJointRegressor.export_onnx`, run with onnxruntime (no PyTorch);
    ``predict`` as :meth:`DepthJointRegressor.predict`, with the crop parameters read from the file.

    Args:
        path: the ``.onnx`` file.
        threads: onnxruntime intra-op threads (0: its default).

    Attributes (after ``fit``): ``session_``, ``crop_`` (the exported crop parameters).
    """

    _fitted = "session_"

    def __init__(self, path: str | os.PathLike, threads: int = 0):
        self.path = path
        self.threads = threads

    def fit(self, sequences=None) -> OnnxDepthJointRegressor:
        """Open the session and read the crop parameters (no training: ``sequences`` is ignored). A ValueError names
        the file when it is not an exported depth joint regressor."""
        from mocapkit.deploy.runtime import cpu_session

        path = Path(self.path)
        if not path.is_file():
            raise ValueError(f"{path}: no such ONNX file")
        _check_number("OnnxDepthJointRegressor", "threads", self.threads, integer=True)
        try:
            session = cpu_session(path, int(self.threads))
            crop = json.loads(session.get_modelmeta().custom_metadata_map.get(ONNX_META_KEY, "{}"))
        except Exception as exc:
            raise ValueError(f"{path}: onnxruntime cannot load it: {exc}") from exc
        if not isinstance(crop, dict) or crop.get("format") != MODEL_FORMAT or crop.get("background") != BACKGROUND:
            raise ValueError(
                f"{path}: not a depth joint regressor export (no {MODEL_FORMAT!r} metadata); write one with "
                f"DepthJointRegressor.export_onnx"
            )
        self.session_, self.crop_ = session, crop
        return self

    def _crop_params(self) -> tuple[int, float, float]:
        c = self.crop_
        return int(c["crop_size"]), float(c["crop_extent_m"]), float(c["depth_scale_m"])

    def _run(self, crops: np.ndarray) -> np.ndarray:
        return self.session_.run(["joints"], {"crops": np.ascontiguousarray(crops, dtype=np.float32)})[0]


class _CropDataset:
    """Every frame of the training sequences as ``(crop float32 [1, S, S], joints float32 [16, 3])``, the joints
    relative to the crop centre (metres), the crop centre shifted and the depths noised per draw (augmentation).

    A map-style dataset (``__len__``, ``__getitem__``) for a ``torch`` DataLoader with no workers: the augmentation
    draws from one generator seeded once, so a seeded fit draws the same crops."""

    def __init__(self, sequences, size, extent_m, depth_scale_m, shift_m, depth_noise_m, seed):
        self.sequences, self.size, self.extent_m, self.depth_scale_m = sequences, size, extent_m, depth_scale_m
        self.shift_m, self.depth_noise_m = shift_m, depth_noise_m
        self.rng = np.random.default_rng(seed)
        index, centres, targets = [], [], []
        for k, seq in enumerate(sequences):
            label = seq.source or "depth sequence"
            joints = tracked_joints(seq.joints).astype(np.float64)
            for t in range(seq.num_frames):
                centre = foreground_centre(seq.depth_mm[t], seq.intrinsics, f"{label}: frame {t}")
                index.append((k, t))
                centres.append(centre)
                targets.append(joints[t] - centre)
        self.index = np.asarray(index, dtype=np.int64)
        self.centres = np.asarray(centres, dtype=np.float64)
        self.targets = np.asarray(targets, dtype=np.float32)

    def __len__(self) -> int:
        return len(self.index)

    def crop(self, i: int, shift: np.ndarray, noise_rng: np.random.Generator | None) -> np.ndarray:
        """Frame ``i``'s crop, its centre moved by ``shift`` ``[2]`` metres (x, y), its foreground depths noised
        with ``noise_rng`` (None: not)."""
        k, t = self.index[i]
        seq = self.sequences[k]
        centre = self.centres[i] + np.array([shift[0], shift[1], 0.0])
        crop = depth_crop(seq.depth_mm[t], seq.intrinsics, centre, self.size, self.extent_m, self.depth_scale_m)
        if noise_rng is not None:
            foreground = crop != BACKGROUND
            noise = noise_rng.normal(0.0, self.depth_noise_m / self.depth_scale_m, int(foreground.sum()))
            crop[foreground] = np.clip(crop[foreground] + noise, -1.0, 1.0)
        return crop

    def __getitem__(self, i):
        import torch

        shift = self.rng.uniform(-self.shift_m, self.shift_m, 2) if self.shift_m > 0 else np.zeros(2)
        crop = self.crop(int(i), shift, self.rng if self.depth_noise_m > 0 else None)
        target = self.targets[i] - np.array([shift[0], shift[1], 0.0], dtype=np.float32)
        return torch.from_numpy(crop[None]), torch.from_numpy(target.astype(np.float32))


__all__ = [
    "BACKGROUND",
    "MODEL_FORMAT",
    "ONNX_META_KEY",
    "DepthJointRegressor",
    "OnnxDepthJointRegressor",
    "depth_crop",
    "depth_crops",
    "foreground_centre",
]
