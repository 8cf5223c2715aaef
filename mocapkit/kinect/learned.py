"""The learned refiners (the BiGRU and the masked transformer of :mod:`mocapkit.models.refiners`) retrained as Kinect
posture correctors, behind the Kinect reconstruction contract of
:class:`~mocapkit.kinect.reconstruction.KinectPostureReconstructor`: ``fit(kinect_clips, mocap_clips,
states)`` and ``predict(kinect_clips, state=...)`` on lists of ``[T, 20, 3]`` metres (y up, joints in
:data:`~mocapkit.motion.layouts.LANDMARK_NAMES` order), so the comparison runner scores it beside Zhou's
GP and the random forest on the same simulated pairs and held-out performers.

**Network.** :class:`~mocapkit.models.refiners.BiGRURefiner` or
:class:`~mocapkit.models.refiners.MaskedTransformerRefiner` (``architecture``), built on the Kinect-20 tree
(:data:`~mocapkit.motion.layouts.LANDMARK_PARENTS`, hips ``l_hip`` / ``r_hip``, the training pairs'
mean bone lengths): the same per-window normalisation (centre, heading, body size) and first guess as when it
refines mocap. By default no Kinect joint is missing, so the missing mask is all False and the network's correction
of the observed posture is the whole output; with ``untracked_as_missing`` the joints the sensor did not track
(tracking state INFERRED or NOT_TRACKED) are given as missing, and the network fills them.

**Training** (:class:`~mocapkit.train.refine_module.MotionRefinementModule`, ``steps`` Adam steps, no logger, no
checkpoint written, seeded by ``random_state``): windows of ``window`` frames (stride ``window // 4``) of every
training pair (:func:`kinect_windows`), the simulated Kinect as input and the mocap as target; every entry counts as
corrupted, so the loss is the mean joint error of the output plus the module's bone-length and velocity terms. A
pair shorter than the window is one window padded at its end with its last frame; the padded frames are marked
missing and not corrupted, so only their bone and velocity terms see them. The Lightning ``Trainer`` is the one
``mocapkit train`` builds (:func:`~mocapkit.train.training.build_estimator_trainer`: ``configs/trainer/default.yaml``, its
``accelerator: auto`` included), with the estimator's ``trainer`` parameter on top
(``trainer={"accelerator": "gpu", "precision": "bf16-mixed"}``).

**Runs.** ``mocapkit train experiment=kinect_corrector_bigru data.root=DIR`` trains the same network on the
simulated pairs of a mocap folder, performers held out (:class:`~mocapkit.kinect.datamodule.KinectPairsDataModule`);
:meth:`LearnedKinectCorrector.from_checkpoint` turns its ``best.ckpt`` into a fitted corrector, ``mocapkit eval``
scores it on the held-out performers (:func:`evaluate_kinect_corrector`) and ``mocapkit export`` writes the ONNX file
``kinect-fix apply`` runs (:func:`export_kinect_corrector_module`).

**Prediction**: each clip in overlapping windows of ``inference_window`` frames (``overlap`` shared, blended with
linear ramps; :func:`~mocapkit.motion.frames.refine_windows`), all of a clip's windows in one batch.

**Export**: :meth:`LearnedKinectCorrector.export_onnx` (``mocapkit kinect-fix export``) writes the network as ONNX with
the corrector's parameters in its metadata; :class:`OnnxKinectCorrector` predicts from that file with onnxruntime
(no PyTorch in the prediction), in the same windows (``mocapkit kinect-fix apply --model FILE.onnx``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from mocapkit.kinect.reconstruction import (
    TRACKED,
    _check_clips,
    _check_nonneg,
    _check_pairs,
    _check_states,
)
from mocapkit.kinect.steady import STEADY_PARAMS, check_steady_params, steady_output
from mocapkit.motion.frames import refine_windows
from mocapkit.motion.layouts import LANDMARK_NAMES, LANDMARK_PARENTS

MODEL_FORMAT = "mocapkit-kinect-corrector-1"
"""The ``format`` field of a saved corrector (:meth:`LearnedKinectCorrector.save`)."""

ARCHITECTURES = {
    "bigru": "mocapkit.models.refiners.refine_bigru",
    "transformer": "mocapkit.models.refiners.refine_transformer",
}

#: The keys of a batch of windows (:func:`window_loader`), in the order of its dataset's tensors.
BATCH_KEYS = ("positions", "clean", "missing", "corrupted")


class _ClipCorrector:
    """``predict`` / ``transform`` of both correctors: the input checks, one clip or a list, then ``_correct``."""

    _fitted: str = ""  # the attribute ``fit`` sets

    def predict(self, kinect, state=None):
        """Correct a clip ``[T, 20, 3]`` metres (or a list of clips) → ``[T, 20, 3]`` metres; ``state`` ``[T, 20]``
        (or a list) is used with ``untracked_as_missing``."""
        check_is_fitted(self, self._fitted)
        if isinstance(kinect, (list, tuple)):
            clips = _check_clips(kinect, "kinect")
            states = _check_states(state, [len(c) for c in clips], "state")
            return [self._correct(c, s) for c, s in zip(clips, states)]
        clip = _check_clips([kinect], "kinect")[0]
        return self._correct(clip, _check_states(None if state is None else [state], [len(clip)], "state")[0])

    transform = predict

    def _correct(self, x: np.ndarray, state: np.ndarray | None) -> np.ndarray:
        raise NotImplementedError


class LearnedKinectCorrector(_ClipCorrector, BaseEstimator):
    """A refiner network trained on (simulated Kinect, mocap) pairs to correct Kinect-20 skeletons (module
    docstring).

    Args:
        architecture: ``"bigru"`` or ``"transformer"`` (the two refiners of :mod:`mocapkit.models.refiners`).
        network: keyword arguments of the network's builder (``{"hidden": 64}`` for the BiGRU, ``{"dim": 64}`` for
            the transformer, ...); None: the builder's defaults, those of the mocap refiners.
        window: training window in frames (64: about 2 s at Kinect's 30 fps).
        steps, batch_size, lr: Adam steps, windows per step, learning rate.
        inference_window, overlap: prediction windows and the frames neighbours share (None: ``2 · window`` and
            ``window // 4``).
        untracked_as_missing: joints whose tracking state is not TRACKED (INFERRED, NOT_TRACKED) go to the network
            as missing, in training and prediction, so it fills them from the tracked joints and frames (the
            refiners' missing mask) instead of correcting their positions; the loss still counts them. False
            (default): the state is not used. Without states every joint counts as tracked.
        bone_weight, velocity_weight: the training loss's steadiness terms
            (:class:`~mocapkit.train.refine_module.MotionRefinementModule`): the mean bone-length error and the mean
            frame-to-frame velocity error against the mocap, beside the joint error (weight 1); 0.1 and 0.5 are the
            mocap refiners' own. Larger values train a steadier corrector.
        tracked_correction, smooth_window, rigid_bones: the output options of :mod:`mocapkit.kinect.steady`, applied
            after the network (the share of the correction a TRACKED joint gets; a zero-lag Savitzky–Golay filter
            of that many frames, 0 off; every bone at the clip's median length).
        random_state: seeds the initialisation and the batches.
        trainer: Lightning ``Trainer`` arguments over ``configs/trainer/default.yaml`` and the estimator's own
            (``max_steps=steps``, no logger, no checkpoint, no progress bar), e.g. ``{"accelerator": "gpu",
            "devices": 1, "precision": "bf16-mixed"}``; None: those defaults (``accelerator: auto``: the CPU where
            there is no GPU).

    Attributes (after ``fit``): ``module_`` (the trained module, eval mode, on the CPU), ``n_windows_``,
    ``loss_curve_`` (float64 ``[steps]``; empty after :meth:`load` and :meth:`from_checkpoint`), ``train_seconds_``.
    :meth:`save` / :meth:`load` write and read one file (``mocapkit kinect-fix train --method bigru`` writes it; the
    ``trainer`` parameter is not saved: it says where to train, not what was learned); :meth:`from_checkpoint`
    reads a ``mocapkit train`` run's checkpoint.
    """

    trains_network = True  # fit trains a network: "learned" in the method registry (mocapkit.train.registry)
    _fitted = "module_"
    #: Parameters used only by :meth:`predict`: the comparison benchmark reuses one fit across them.
    predict_params = ("inference_window", "overlap", *STEADY_PARAMS)

    def __init__(
        self,
        architecture: str = "bigru",
        network: dict | None = None,
        window: int = 64,
        steps: int = 1000,
        batch_size: int = 32,
        lr: float = 1e-3,
        inference_window: int | None = None,
        overlap: int | None = None,
        untracked_as_missing: bool = False,
        bone_weight: float = 0.1,
        velocity_weight: float = 0.5,
        tracked_correction: float = 1.0,
        smooth_window: int = 0,
        rigid_bones: bool = False,
        random_state: int | None = 0,
        trainer: dict | None = None,
    ):
        self.architecture = architecture
        self.network = network
        self.window = window
        self.steps = steps
        self.batch_size = batch_size
        self.lr = lr
        self.inference_window = inference_window
        self.overlap = overlap
        self.untracked_as_missing = untracked_as_missing
        self.bone_weight = bone_weight
        self.velocity_weight = velocity_weight
        self.tracked_correction = tracked_correction
        self.smooth_window = smooth_window
        self.rigid_bones = rigid_bones
        self.random_state = random_state
        self.trainer = trainer

    # ------------------------------------------------------------------ fit
    def _check_params(self) -> None:
        if self.architecture not in ARCHITECTURES:
            raise ValueError(
                f"LearnedKinectCorrector: architecture must be one of {list(ARCHITECTURES)}, got {self.architecture!r}"
            )
        if self.network is not None and not isinstance(self.network, Mapping):
            raise ValueError(
                f"LearnedKinectCorrector: network must be a dict of builder arguments or None, got "
                f"{type(self.network).__name__}"
            )
        for name in ("steps", "batch_size"):
            _check_nonneg(name, getattr(self, name), integer=True, minimum=1)
        _check_nonneg("window", self.window, integer=True, minimum=4)
        _check_nonneg("lr", self.lr)
        _check_nonneg("bone_weight", self.bone_weight)
        _check_nonneg("velocity_weight", self.velocity_weight)
        check_steady_params(self.tracked_correction, self.smooth_window, self.rigid_bones, "LearnedKinectCorrector")
        if self.inference_window is not None:
            _check_nonneg("inference_window", self.inference_window, integer=True, minimum=4)
        if self.overlap is not None:
            _check_nonneg("overlap", self.overlap, integer=True)
        if not isinstance(self.untracked_as_missing, (bool, np.bool_)):
            raise ValueError(  # noqa: TRY004 (a bad parameter value, as every check here)
                f"LearnedKinectCorrector: untracked_as_missing must be True or False, got {self.untracked_as_missing!r}"
            )
        from mocapkit.train.training import check_trainer_parameter

        check_trainer_parameter(self.trainer, "LearnedKinectCorrector")

    def _module(self, bone_lengths: list[float]):
        """A fresh :class:`~mocapkit.train.refine_module.MotionRefinementModule` of this corrector's network on the
        Kinect-20 tree with the given mean bone lengths (``[20]`` m, 0 for the root)."""
        from mocapkit.train.refine_module import MotionRefinementModule

        return MotionRefinementModule(
            model={"_target_": ARCHITECTURES[self.architecture], **dict(self.network or {})},
            optimizer={"_target_": "torch.optim.Adam", "_partial_": True, "lr": float(self.lr), "fused": True},
            skeleton=kinect_skeleton(bone_lengths),
            bone_weight=float(self.bone_weight),
            velocity_weight=float(self.velocity_weight),
        )

    def fit(self, kinect_clips, mocap_clips, states=None) -> LearnedKinectCorrector:
        """Train on paired clips (lists of ``[T, 20, 3]`` metres) and their tracking states (lists of ``[T, 20]``,
        used with ``untracked_as_missing``)."""
        import lightning as L

        from mocapkit.train.training import build_estimator_trainer

        self._check_params()
        kinect, mocap = _check_pairs(kinect_clips, mocap_clips)
        states = _check_states(states, [len(c) for c in kinect], "states")
        windows = kinect_windows(kinect, mocap, states, self.window, self.untracked_as_missing)
        self.n_windows_ = len(windows["positions"])
        L.seed_everything(0 if self.random_state is None else int(self.random_state), workers=False, verbose=False)
        module = self._module(mean_bone_lengths(mocap))
        curve: list[float] = []

        class _Record(L.Callback):
            def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx):
                curve.append(float(outputs["loss"]) if isinstance(outputs, dict) else float(outputs))

        trainer = build_estimator_trainer(self.steps, self.trainer, callbacks=[_Record()])
        start = time.perf_counter()
        trainer.fit(module, train_dataloaders=window_loader(windows, int(self.batch_size), shuffle=True))
        self.train_seconds_ = time.perf_counter() - start
        self.loss_curve_ = np.asarray(curve, dtype=np.float64)
        self.module_ = module.cpu().eval()
        return self

    @classmethod
    def from_checkpoint(cls, path: str | os.PathLike, **params) -> LearnedKinectCorrector:
        """A fitted corrector from a checkpoint of a ``mocapkit train experiment=kinect_corrector_*`` run
        (``RUN/best.ckpt``; read with ``weights_only=True`` and vetted, :mod:`mocapkit.train.checkpoints`): the
        architecture, network arguments, window, tracking-state use and learning rate come from the checkpoint,
        ``params`` (``inference_window``, ``overlap``, ...) are set on top. A ValueError names the file when it is
        not a Kinect corrector's checkpoint."""
        import io

        from mocapkit.train.checkpoints import parse_checkpoint, read_checkpoint_bytes, restore_error_detail
        from mocapkit.train.refine_module import MotionRefinementModule

        raw = read_checkpoint_bytes(path)
        hparams = parse_checkpoint(raw, path).get("hyper_parameters", {})
        skeleton, model = dict(hparams.get("skeleton") or {}), dict(hparams.get("model") or {})
        if (
            list(skeleton.get("joint_names", [])) != list(LANDMARK_NAMES)
            or "window" not in skeleton
            or model.get("_target_") not in ARCHITECTURES.values()
        ):
            raise ValueError(
                f"{path}: not a Kinect corrector checkpoint (a refiner network on the Kinect-20 joints "
                f"with its training window); train one with `mocapkit train "
                f"experiment=kinect_corrector_bigru data.root=DIR`"
            )
        try:
            module = MotionRefinementModule.load_from_checkpoint(io.BytesIO(raw), map_location="cpu", weights_only=True)
        except Exception as exc:  # weights of another network version, hyper-parameters the class does not take
            raise ValueError(f"{path}: cannot restore the corrector from it: {restore_error_detail(exc)}") from exc
        return cls.from_module(module, **params)

    @classmethod
    def from_module(cls, module, **params) -> LearnedKinectCorrector:
        """A fitted corrector around a trained :class:`~mocapkit.train.refine_module.MotionRefinementModule` of a
        ``kinect_corrector`` run (its ``skeleton`` hyper-parameters hold ``window`` and ``untracked_as_missing``)."""
        hparams = module.hparams
        skeleton, model = dict(hparams["skeleton"]), dict(hparams["model"])
        architecture = {target: name for name, target in ARCHITECTURES.items()}[model["_target_"]]
        network = {k: v for k, v in model.items() if not str(k).startswith("_")}
        corrector = cls(
            architecture=architecture,
            network=network,
            window=int(skeleton["window"]),
            lr=float(hparams["optimizer"].get("lr", 1e-3)),
            untracked_as_missing=bool(skeleton.get("untracked_as_missing", False)),
            bone_weight=float(hparams.get("bone_weight", 0.1)),
            velocity_weight=float(hparams.get("velocity_weight", 0.5)),
        ).set_params(**params)
        corrector._check_params()
        corrector.module_ = module.cpu().eval()
        corrector.n_windows_, corrector.train_seconds_, corrector.loss_curve_ = 0, float("nan"), np.zeros(0)
        return corrector

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike) -> Path:
        """Write the fitted corrector as one ``torch.save`` file of plain values and tensors (its parameters, the
        bone lengths, the network's weights; nothing to unpickle beyond what ``weights_only=True`` loads), atomically;
        parent folders are created."""
        import torch

        from mocapkit.io_atomic import atomic_open

        check_is_fitted(self, "module_")
        params = {k: v for k, v in self.get_params(deep=False).items() if k != "trainer"}
        params["network"] = None if self.network is None else {str(k): v for k, v in dict(self.network).items()}
        state = {
            "format": MODEL_FORMAT,
            "params": params,
            "bone_lengths": [float(v) for v in self.module_.hparams["skeleton"]["bone_lengths"]],
            "n_windows": int(self.n_windows_),
            "train_seconds": float(self.train_seconds_),
            "state_dict": {k: v.detach().clone() for k, v in self.module_.model.state_dict().items()},
        }
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(path, "wb") as f:
            torch.save(state, f)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> LearnedKinectCorrector:
        """A corrector written by :meth:`save` (read with ``weights_only=True``; the network is one of
        :data:`ARCHITECTURES`, never a class named by the file); a ValueError names the file when it is not one."""
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
            module = model._module(state["bone_lengths"])
            module.model.load_state_dict(state["state_dict"])
        except Exception as exc:
            raise ValueError(
                f"{path}: not a Kinect corrector written by LearnedKinectCorrector.save / mocapkit "
                f"kinect-fix train --method bigru|transformer ({exc})"
            ) from exc
        model.module_ = module.eval()
        model.n_windows_, model.train_seconds_ = state["n_windows"], state["train_seconds"]
        model.loss_curve_ = np.zeros(0)
        return model

    # ------------------------------------------------------------------ predict
    def _correct(self, x: np.ndarray, state: np.ndarray | None) -> np.ndarray:
        import torch

        def run(positions: np.ndarray, missing: np.ndarray) -> np.ndarray:
            with torch.inference_mode():
                return self.module_(torch.from_numpy(positions), torch.from_numpy(missing)).numpy()

        corrected = correct_in_windows(
            run, x, state, self.untracked_as_missing, self.window, self.inference_window, self.overlap
        )
        return steady_output(x, corrected, state, self.tracked_correction, self.smooth_window, self.rigid_bones)

    # ------------------------------------------------------------------ export
    def export_onnx(self, path: str | os.PathLike, **check) -> dict:
        """Write the network as ONNX (:func:`~mocapkit.deploy.refiner_export.export_refiner`: inputs ``positions``
        ``[batch, frames, 20, 3]`` metres and ``missing`` ``[batch, frames, 20]``, output ``refined``; normalisation
        inside the graph; parity with PyTorch checked by onnxruntime on shapes other than the traced one), with this
        corrector's parameters in the metadata so :class:`OnnxKinectCorrector` predicts as :meth:`predict` does.
        ``check``: ``opset``, ``trace_shape``, ``check_shape``, ``atol``, ``rtol`` of the export. Returns its
        figures."""
        from mocapkit.deploy.refiner_export import export_refiner

        check_is_fitted(self, "module_")
        skeleton = {
            **dict(self.module_.hparams["skeleton"]),
            "kinect_corrector": {
                "format": MODEL_FORMAT,
                "architecture": self.architecture,
                "window": int(self.window),
                "inference_window": self.inference_window,
                "overlap": self.overlap,
                "untracked_as_missing": bool(self.untracked_as_missing),
                "tracked_correction": float(self.tracked_correction),
                "smooth_window": int(self.smooth_window),
                "rigid_bones": bool(self.rigid_bones),
            },
        }
        return export_refiner(self.module_.model, path, skeleton, **check)


class OnnxKinectCorrector(_ClipCorrector, BaseEstimator):
    """A corrector exported by :meth:`LearnedKinectCorrector.export_onnx` (``mocapkit kinect-fix export``), run with
    onnxruntime (the network never runs in PyTorch; ``kinect-fix`` still imports it, through
    :mod:`mocapkit.classical`); ``predict`` as :meth:`LearnedKinectCorrector.predict` (the same windows and
    tracking-state use, read from the file's metadata).

    Args:
        path: the ``.onnx`` file.
        inference_window, overlap: prediction windows and shared frames (None: the exported corrector's).
        threads: onnxruntime intra-op threads (0: its default).

    Attributes (after ``fit``): ``session_``, ``corrector_`` (the exported corrector's parameters).
    """

    _fitted = "session_"

    def __init__(
        self, path: str | os.PathLike, inference_window: int | None = None, overlap: int | None = None, threads: int = 0
    ):
        self.path = path
        self.inference_window = inference_window
        self.overlap = overlap
        self.threads = threads

    def fit(self, kinect_clips=None, mocap_clips=None, states=None) -> OnnxKinectCorrector:
        """Open the session and read the corrector's parameters (no training: the clips are ignored). A ValueError
        names the file when it is not an exported Kinect corrector."""
        import json

        from mocapkit.deploy.runtime import cpu_session

        path = Path(self.path)
        if not path.is_file():
            raise ValueError(f"{path}: no such ONNX file")
        for name in ("inference_window", "overlap"):
            if getattr(self, name) is not None:
                _check_nonneg(name, getattr(self, name), integer=True, minimum=4 if name == "inference_window" else 0)
        _check_nonneg("threads", self.threads, integer=True)
        try:
            session = cpu_session(path, int(self.threads))
            skeleton = json.loads(session.get_modelmeta().custom_metadata_map.get("mocapkit_skeleton", "{}"))
        except Exception as exc:
            raise ValueError(f"{path}: onnxruntime cannot load it: {exc}") from exc
        corrector = skeleton.get("kinect_corrector")
        if (
            not isinstance(corrector, dict)
            or corrector.get("format") != MODEL_FORMAT
            or list(skeleton.get("joint_names", [])) != list(LANDMARK_NAMES)
        ):
            raise ValueError(
                f"{path}: not a Kinect corrector export (no {MODEL_FORMAT!r} metadata on the Kinect-20 "
                f"joints); write one with `mocapkit kinect-fix export --model MODEL.pt --out FILE.onnx`"
            )
        self.session_, self.corrector_ = session, corrector
        return self

    def _correct(self, x: np.ndarray, state: np.ndarray | None) -> np.ndarray:
        def run(positions: np.ndarray, missing: np.ndarray) -> np.ndarray:
            return self.session_.run(["refined"], {"positions": positions, "missing": missing})[0]

        c = self.corrector_
        corrected = correct_in_windows(
            run,
            x,
            state,
            bool(c["untracked_as_missing"]),
            int(c["window"]),
            c["inference_window"] if self.inference_window is None else self.inference_window,
            c["overlap"] if self.overlap is None else self.overlap,
        )
        return steady_output(
            x,
            corrected,
            state,
            float(c.get("tracked_correction", 1.0)),
            int(c.get("smooth_window", 0)),
            bool(c.get("rigid_bones", False)),
        )


def network_missing(state: np.ndarray | None, frames: int, untracked_as_missing: bool) -> np.ndarray:
    """``[T, 20]`` bool: the joints the network gets as missing — those not TRACKED with ``untracked_as_missing``,
    none otherwise (or without states)."""
    if not untracked_as_missing or state is None:
        return np.zeros((frames, len(LANDMARK_NAMES)), dtype=bool)
    return state != TRACKED


def kinect_windows(
    kinect: list[np.ndarray],
    mocap: list[np.ndarray],
    states: list[np.ndarray | None],
    window: int,
    untracked_as_missing: bool,
) -> dict[str, np.ndarray]:
    """The training windows of paired clips (module docstring): ``{"positions", "clean": [N, W, 20, 3] float32,
    "missing", "corrupted": [N, W, 20] bool}`` (``N`` is 0 without clips); ``missing`` holds the padding and, with
    ``untracked_as_missing``, the joints not tracked (:func:`network_missing`)."""
    W, stride, J = int(window), max(1, int(window) // 4), len(LANDMARK_NAMES)
    noisy, clean, unseen, padded = [], [], [], []
    for k, m, state in zip(kinect, mocap, states):
        T, hidden = len(k), network_missing(state, len(k), untracked_as_missing)
        if T < W:
            pad = W - T
            noisy.append(np.concatenate([k, np.repeat(k[-1:], pad, axis=0)]))
            clean.append(np.concatenate([m, np.repeat(m[-1:], pad, axis=0)]))
            unseen.append(np.concatenate([hidden, np.ones((pad, hidden.shape[1]), dtype=bool)]))
            padded.append(np.arange(W) >= T)
            continue
        starts = list(range(0, T - W + 1, stride))
        if starts[-1] != T - W:
            starts.append(T - W)
        noisy += [k[s : s + W] for s in starts]
        clean += [m[s : s + W] for s in starts]
        unseen += [hidden[s : s + W] for s in starts]
        padded += [np.zeros(W, dtype=bool)] * len(starts)
    if not noisy:
        return {
            "positions": np.zeros((0, W, J, 3), np.float32),
            "clean": np.zeros((0, W, J, 3), np.float32),
            "missing": np.zeros((0, W, J), bool),
            "corrupted": np.zeros((0, W, J), bool),
        }
    padded = np.repeat(np.stack(padded)[:, :, None], J, axis=2)
    return {
        "positions": np.stack(noisy).astype(np.float32),
        "clean": np.stack(clean).astype(np.float32),
        "missing": np.stack(unseen) | padded,
        "corrupted": ~padded,
    }


def window_loader(windows: dict[str, np.ndarray], batch_size: int, shuffle: bool, num_workers: int = 0):
    """A ``torch`` DataLoader of :func:`kinect_windows` as batch dicts (``positions``, ``clean``: ``[B, W, 20, 3]``;
    ``missing``, ``corrupted``: ``[B, W, 20]``); with ``shuffle`` (training) the order is drawn every epoch and the
    last incomplete batch dropped when there is more than one batch."""
    import torch

    data = torch.utils.data.TensorDataset(*(torch.from_numpy(np.ascontiguousarray(windows[k])) for k in BATCH_KEYS))
    return torch.utils.data.DataLoader(
        data,
        batch_size=int(batch_size),
        shuffle=shuffle,
        drop_last=shuffle and len(data) > int(batch_size),
        collate_fn=_batch,
        num_workers=num_workers,
        persistent_workers=num_workers > 0,
    )


def _batch(items: list[tuple]) -> dict:
    """One batch dict of :func:`window_loader` from its dataset's items (a module-level function: workers pickle it)."""
    import torch

    return {key: torch.stack([item[i] for item in items]) for i, key in enumerate(BATCH_KEYS)}


def mean_bone_lengths(mocap: list[np.ndarray]) -> list[float]:
    """``[20]`` metres: each Kinect-20 bone's length averaged over every frame of ``mocap`` (0 for the root)."""
    child = [j for j, p in enumerate(LANDMARK_PARENTS) if p >= 0]
    pooled = np.concatenate(mocap)
    lengths = np.zeros(len(LANDMARK_NAMES))
    lengths[child] = np.linalg.norm(pooled[:, child] - pooled[:, [LANDMARK_PARENTS[j] for j in child]], axis=-1).mean(
        axis=0
    )
    return [float(v) for v in lengths]


def kinect_skeleton(bone_lengths: list[float], fps: float | None = None) -> dict:
    """The refiner networks' layout arguments on the Kinect-20 tree (hips ``l_hip`` / ``r_hip``), with the given
    mean bone lengths (``[20]`` m, 0 for the root) and frame rate (None: not recorded)."""
    return {
        "joint_names": list(LANDMARK_NAMES),
        "parents": list(LANDMARK_PARENTS),
        "up_axis": "y",
        "hips": [LANDMARK_NAMES.index("l_hip"), LANDMARK_NAMES.index("r_hip")],
        "bone_lengths": [float(v) for v in bone_lengths],
        "fps": fps,
    }


def evaluate_kinect_corrector(module, datamodule, cfg, out_dir: Path) -> dict:
    """``mocapkit eval ckpt_path=RUN/best.ckpt`` of a ``kinect_corrector`` run: the corrector
    (:meth:`LearnedKinectCorrector.from_module`) on the pairs of the run's ``eval.part`` (``test``: the held-out
    performers), scored as the Kinect benchmark scores a cell (:func:`~mocapkit.kinect.metrics.joint_error_cm`,
    frame-weighted over the clips): ``error_cm``, ``raw_cm`` (the simulated Kinect's own), ``reduction`` and the
    per-joint errors; written to ``out_dir/results.json``."""
    import json

    from mocapkit.io_atomic import atomic_write_text
    from mocapkit.kinect.metrics import joint_error_cm

    kinect, mocap, states = datamodule.parts[cfg.eval.part]
    if not kinect:
        raise ValueError(f"eval.part={cfg.eval.part}: the run's data has no {cfg.eval.part} clip")
    corrected = LearnedKinectCorrector.from_module(module).predict(kinect, state=states)
    frames = np.array([len(m) for m in mocap], dtype=np.float64)
    per_joint = sum(joint_error_cm(c, m, per_joint=True) * len(m) for c, m in zip(corrected, mocap)) / frames.sum()
    raw = sum(joint_error_cm(k, m, per_joint=True) * len(m) for k, m in zip(kinect, mocap)) / frames.sum()
    report = {
        "part": cfg.eval.part,
        "groups": datamodule.groups["test" if cfg.eval.part == "test" else "train"],
        "clips": len(mocap),
        "frames": int(frames.sum()),
        "error_cm": float(per_joint.mean()),
        "raw_cm": float(raw.mean()),
        "reduction": float(1.0 - per_joint.mean() / raw.mean()),
        "per_joint_cm": dict(zip(LANDMARK_NAMES, per_joint.round(3).tolist())),
        "per_joint_raw_cm": dict(zip(LANDMARK_NAMES, raw.round(3).tolist())),
    }
    atomic_write_text(Path(out_dir) / "results.json", json.dumps(report, indent=1))
    print(
        f"[mocapkit] {cfg.eval.part} ({report['clips']} clips, {report['frames']} frames): error "
        f"{report['error_cm']:.2f} cm, raw {report['raw_cm']:.2f} cm, reduction {100 * report['reduction']:.1f} %; "
        f"wrote {Path(out_dir) / 'results.json'}"
    )
    return report


def export_kinect_corrector_module(module, target: Path, export_cfg) -> dict:
    """``mocapkit export ckpt_path=RUN/best.ckpt`` of a ``kinect_corrector`` run: the module as a corrector
    (:meth:`LearnedKinectCorrector.from_module`) exported with :meth:`LearnedKinectCorrector.export_onnx` and the
    ``export`` config node's shapes and tolerances; ``mocapkit kinect-fix apply --model FILE.onnx`` runs it."""
    return LearnedKinectCorrector.from_module(module).export_onnx(
        target,
        opset=export_cfg.opset,
        trace_shape=(export_cfg.trace_batch, export_cfg.trace_frames),
        check_shape=(export_cfg.check_batch, export_cfg.check_frames),
        atol=export_cfg.atol,
        rtol=export_cfg.rtol,
    )


def correct_in_windows(
    run,
    x: np.ndarray,
    state: np.ndarray | None,
    untracked_as_missing: bool,
    window: int,
    inference_window: int | None,
    overlap: int | None,
) -> np.ndarray:
    """One clip ``x`` ``[T, 20, 3]`` through ``run(positions [N, W, 20, 3] float32, missing [N, W, 20]) -> [N, W,
    20, 3]`` in overlapping windows of ``inference_window`` frames (None: ``2 · window``) sharing ``overlap``
    (None: ``window // 4``); the result in ``x``'s dtype."""
    size = int(inference_window) if inference_window is not None else 2 * int(window)
    shared = int(overlap) if overlap is not None else int(window) // 4
    missing = network_missing(state, len(x), untracked_as_missing)
    return refine_windows(run, x.astype(np.float32), missing, size, shared).astype(x.dtype)


__all__ = [
    "ARCHITECTURES",
    "MODEL_FORMAT",
    "LearnedKinectCorrector",
    "OnnxKinectCorrector",
    "correct_in_windows",
    "evaluate_kinect_corrector",
    "export_kinect_corrector_module",
    "kinect_skeleton",
    "kinect_windows",
    "mean_bone_lengths",
    "network_missing",
    "window_loader",
]
