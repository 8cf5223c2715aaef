"""Contract checks for the methods of every task, in the manner of scikit-learn's ``check_estimator``.

Each ``check_*`` function takes a freshly built, unfitted method and small data, and raises ``AssertionError``
(naming the method and what broke) when the method does not keep its task's contract. ``tests/<task>/
test_contract.py`` runs them on every name of the method registry (:mod:`mocapkit.train.registry`), so a new
method gets them by adding its config file. Shared by every task:

- :func:`check_parameters`: ``__init__`` stores the config's values untouched (``get_params`` equals the node, nested
  estimators too), ``clone`` works, and scikit-learn's own ``check_no_attributes_set_in_init``,
  ``check_get_params_invariance`` and ``check_set_params`` pass.

Per task (units: metres, frames; shapes in the docstrings):

- :func:`check_refiner` — :class:`~mocapkit.refinement.base.MotionRefiner`;
- :func:`check_retrieval_method` — :class:`~mocapkit.retrieval.base.RetrievalMethod` (with the save/load of its
  state);
- :func:`check_synthesizer` — :class:`~mocapkit.synthesis.base.MotionSynthesizer`;
- :func:`check_kinect_corrector` — ``fit(kinect_clips, mocap_clips, states)`` / ``predict(kinect, state)`` (with
  ``save`` / ``load`` where the method has them);
- :func:`check_depth_estimator` — ``fit(sequences)`` / ``predict(sequence) -> [T, 16, 3]`` on depth video
  (:mod:`mocapkit.depth_tracking.base`; with ``save`` / ``load`` where the method has them);
- :func:`check_sequence_classifier` — a scikit-learn classifier of skeleton sequences (recognition, clustering);
- :func:`check_gait_classifier` — a scikit-learn classifier of GEIs (gait).

Networks trained by ``mocapkit train`` are registry entries that name their experiment
(``{experiment: NAME}``): :func:`training_run_experiment` tells them apart and :func:`check_training_run_entry` checks
one (its keys are the comparison runner's, its experiment composes, and ``build_method`` refuses it naming the
command that trains it).

Data helpers: :func:`synthetic_clips` (ASF/AMC clips of :mod:`mocapkit.datasets.synthetic.hdm05`, read back),
:func:`kinect_pairs` (their simulated Kinect pairs) and :func:`depth_sequences` (their rendered depth video).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from sklearn.base import clone
from sklearn.exceptions import NotFittedError


def _name(estimator) -> str:
    return type(estimator).__name__


# ------------------------------------------------------------------------------------------ data


def synthetic_clips(
    folder: str | os.PathLike,
    classes: Sequence[str] = ("hopBothLegs1hops", "squat1Reps"),
    actors: Sequence[str] = ("bd", "bk"),
    clips_per_actor: int = 2,
    fps: float = 30.0,
    max_frames: int = 60,
    seed: int = 0,
) -> list:
    """Short HDM05-style ASF/AMC clips (31 joints, metres) written by the synthetic generator into ``folder`` and
    read back, sorted by file name (class, actor, take); ``Motion.name`` holds the class in its stem."""
    from mocapkit.datasets.formats.asf_amc import read_amc
    from mocapkit.datasets.synthetic.hdm05 import HDM05SynthConfig, synthesize_hdm05

    config = HDM05SynthConfig(
        classes=tuple(classes),
        actors=tuple(actors),
        clips_per_actor=clips_per_actor,
        fps=fps,
        max_frames=max_frames,
        seed=seed,
    )
    files = synthesize_hdm05(folder, config, progress=False)
    return [read_amc(path) for path in sorted(Path(p) for p in files)]


def kinect_pairs(paths: Sequence[str | os.PathLike], seed: int = 0) -> list:
    """Simulated (Kinect, mocap) pairs of motion files at 30 fps: ``.noisy`` / ``.clean`` ``[T, 20, 3]`` metres,
    ``.state`` ``[T, 20]`` tracking states."""
    from mocapkit.datasets.synthetic.kinect_noise import KinectNoiseConfig, simulate_pairs

    pairs, skipped = simulate_pairs(paths, KinectNoiseConfig.preset("mean_error"), seed=seed, fps=30.0, progress=False)
    assert not skipped, skipped
    return pairs


def depth_sequences(
    folder: str | os.PathLike,
    clips: int = 3,
    frames: int = 20,
    camera: str = "kinect_v1",
    seed: int = 0,
) -> list:
    """``clips`` tiny depth videos (:class:`~mocapkit.datasets.formats.depth_images.DepthSequence`, every field
    filled, ``frames`` frames at 30 fps) of :func:`synthetic_clips` written into ``folder``, rendered by
    :func:`~mocapkit.datasets.synthetic.depth.render_depth_sequence`; ``source`` is each clip's file name. In
    file-name order (class, actor, take): with 3 clips, the last is another action than the first two."""
    from mocapkit.datasets.synthetic.depth import render_depth_sequence
    from mocapkit.datasets.synthetic.kinect_noise import kinect20_from_motion

    # 2 classes × 2 actors per take number: as many takes as the clips need
    motions = synthetic_clips(folder, clips_per_actor=-(-clips // 4), max_frames=frames, seed=seed)[:clips]
    out = []
    for k, motion in enumerate(motions):
        # the generator wrote 30 fps; AMC files carry no rate and read as 120 fps: keep every frame
        positions = kinect20_from_motion(motion, fps=None)[:frames]
        source = Path(motion.source or f"clip{k}").name
        out.append(render_depth_sequence(positions, 30.0, camera=camera, seed=seed + k, source=source))
    return out


# ------------------------------------------------------------------------------------------ every task


def _matches(value, expected) -> bool:
    """A parameter value against its config value (a nested ``_target_`` node: the estimator's params)."""
    if isinstance(expected, dict) and "_target_" in expected:
        if not hasattr(value, "get_params"):
            return False
        params = value.get_params(deep=False)
        return all(k.startswith("_") or (k in params and _matches(params[k], v)) for k, v in expected.items())
    if isinstance(expected, (list, tuple)) and isinstance(value, (list, tuple)):
        return len(value) == len(expected) and all(_matches(a, b) for a, b in zip(value, expected))
    if isinstance(expected, dict) and isinstance(value, dict):
        return value.keys() == expected.keys() and all(_matches(value[k], expected[k]) for k in expected)
    return value == expected


def check_parameters(estimator, config: dict) -> None:
    """``__init__`` stores the config's parameters untouched; ``clone`` and scikit-learn's parameter checks pass.

    ``config`` is the method's node as plain containers (``_target_`` and nested nodes included). A
    ``make_pipeline`` node (``_args_``) is compared step by step.
    """
    from sklearn.utils.estimator_checks import (
        check_get_params_invariance,
        check_no_attributes_set_in_init,
        check_set_params,
    )

    name = _name(estimator)
    if "_args_" in config:  # make_pipeline(*steps): the steps are the nodes
        steps = [step for _, step in estimator.steps]
        assert len(steps) == len(config["_args_"]), f"{name}: {len(steps)} steps, config {len(config['_args_'])}"
        for step, node in zip(steps, config["_args_"]):
            check_parameters(step, node)
    else:
        params = estimator.get_params(deep=False)
        for key, expected in config.items():
            if key.startswith("_"):
                continue
            assert key in params, f"{name}: the config's parameter {key!r} is not one of get_params()"
            assert _matches(params[key], expected), (
                f"{name}: __init__ changed {key}: config {expected!r}, get_params {params[key]!r}"
            )
    copy = clone(estimator)
    assert type(copy) is type(estimator) and copy is not estimator, f"{name}: clone"
    assert copy.get_params(deep=False).keys() == estimator.get_params(deep=False).keys() and repr(copy) == repr(
        estimator
    ), f"{name}: clone changed the parameters: {copy!r} != {estimator!r}"
    check_no_attributes_set_in_init(name, clone(estimator))
    check_get_params_invariance(name, clone(estimator))
    check_set_params(name, clone(estimator))


def _raises(exceptions, call, what: str) -> Exception:
    try:
        call()
    except exceptions as exc:  # the expected error: returned so callers can look at its message
        return exc
    raise AssertionError(f"{what}: no error raised (expected {exceptions})")


# ------------------------------------------------------------------------------------------ training runs


def registered_names(task: str) -> tuple[list[str], list[str]]:
    """``(estimators, networks)``: the registry names of ``task`` built by ``build_method``, and those naming a
    ``mocapkit train`` experiment."""
    from mocapkit.train.registry import method_names

    names = method_names(task)
    networks = [name for name in names if training_run_experiment(task, name)]
    return [name for name in names if name not in networks], networks


def required_parameters(task: str, name: str) -> list[str]:
    """The parameters the entry leaves required (``???``: the file of a trained network)."""
    from omegaconf import OmegaConf

    from mocapkit.train.registry import method_config

    node = OmegaConf.to_container(method_config(task, name))
    return [key for key, value in node.items() if value == "???"]


def check_registered_parameters(task: str, name: str, overrides: Sequence[str] = ()) -> None:
    """:func:`check_parameters` on the entry built with ``overrides``, against its composed config."""
    from omegaconf import OmegaConf

    from mocapkit.train.registry import build_method, method_config

    config = OmegaConf.to_container(method_config(task, name, overrides))
    check_parameters(build_method(task, name, overrides), config)


def training_run_experiment(task: str, name: str) -> str | None:
    """The experiment a registry entry names when the method is a network trained by ``mocapkit train`` (else None)."""
    from omegaconf import OmegaConf

    from mocapkit.train.registry import method_config

    return OmegaConf.to_container(method_config(task, name)).get("experiment")


def check_training_run_entry(task: str, name: str) -> None:
    """A network of the task: its entry holds only the comparison runner's ``learned`` keys, its experiment composes
    with ``mocapkit train``'s config, and ``build_method`` refuses it naming ``mocapkit train experiment=NAME``."""
    from omegaconf import OmegaConf

    from mocapkit.evaluation.compare.runner import LEARNED_KEYS
    from mocapkit.train.config import compose_config
    from mocapkit.train.errors import ConfigError
    from mocapkit.train.registry import build_method, method_config

    entry = OmegaConf.to_container(method_config(task, name))
    assert set(entry) <= set(LEARNED_KEYS), f"{task}/{name}: keys {sorted(entry)} beyond {sorted(LEARNED_KEYS)}"
    experiment = entry["experiment"]
    assert compose_config([f"experiment={experiment}"]).get("module") is not None, f"{task}/{name}: {experiment}"
    error = _raises(ConfigError, lambda: build_method(task, name), f"{task}/{name}: build_method")
    assert f"mocapkit train experiment={experiment}" in str(error), f"{task}/{name}: {error}"


# ------------------------------------------------------------------------------------------ refinement


def _with_gaps(motion, seed: int = 0):
    """``motion`` with one interior gap of 6 frames in 3 joints and 3 % random missing samples (kept away from the
    first and last frames, which interpolations leave missing)."""
    from dataclasses import replace

    rng = np.random.default_rng(seed)
    frames, joints = motion.positions.shape[:2]
    missing = np.zeros((frames, joints), bool)
    start = frames // 2 - 3
    missing[start : start + 6, rng.choice(joints, 3, replace=False)] = True
    inner = rng.random((frames - 4, joints)) < 0.03
    missing[2:-2] |= inner
    positions = motion.positions.copy()
    positions[missing] = np.nan
    return replace(motion, positions=positions, missing=missing, rotations=None)


def check_refiner(refiner, train: Sequence, clean) -> None:
    """The :class:`~mocapkit.refinement.base.MotionRefiner` contract on ``clean`` (a complete motion ``[T, J, 3]``
    metres, not in ``train``) with gaps made in it.

    - before ``fit``: a data-driven refiner (``requires_fit``) raises ``NotFittedError``; another refines as it
      does after ``fit()`` without motions;
    - ``refine`` keeps the frames, joints, fps and every observed sample (bit for bit unless the method reports
      repairs), fills interior gaps with finite values within 1 m of the truth (metres, not millimetres), and
      marks as missing exactly the samples it left NaN;
    - bad input: NaN in an observed sample, and a motion of another layout for a data-driven refiner, raise a
      ``ValueError`` naming the problem.
    """
    from dataclasses import replace

    name = _name(refiner)
    gappy = _with_gaps(clean)
    if refiner.requires_fit:
        _raises(NotFittedError, lambda: refiner.refine(gappy), f"{name}.refine before fit")
        fitted = refiner.fit(list(train))
    else:
        before = refiner.refine(gappy)
        fitted = clone(refiner).fit()
        after = fitted.refine(gappy)
        assert np.array_equal(before.positions, after.positions, equal_nan=True), (
            f"{name}: refine before fit differs from refine after fit() (it learns nothing)"
        )
    assert fitted is not None, f"{name}.fit must return the refiner"
    out = fitted.refine(gappy)
    assert out.positions.shape == clean.positions.shape, f"{name}: shape {out.positions.shape}"
    assert out.joint_names == clean.joint_names and out.fps == clean.fps, f"{name}: joints or fps changed"
    observed = ~gappy.missing
    report = out.metadata.get("refinement", {})
    moved = observed & ~np.all(out.positions == gappy.positions, axis=-1)
    assert moved.sum() <= report.get("repaired", 0), (
        f"{name}: {moved.sum()} observed samples changed, {report.get('repaired', 0)} reported repaired"
    )
    assert np.array_equal(out.missing, ~np.all(np.isfinite(out.positions), axis=-1)), (
        f"{name}: missing does not mark the NaN samples"
    )
    filled = gappy.missing & ~out.missing
    assert filled.sum() > 0.5 * gappy.missing.sum(), (
        f"{name}: filled {filled.sum()} of {gappy.missing.sum()} missing samples"
    )
    error = np.linalg.norm(out.positions[filled] - clean.positions[filled], axis=-1)
    assert np.all(error < 1.0), f"{name}: filled samples up to {error.max():.2f} m from the truth"
    bad = gappy.positions.copy()
    bad[0, 0] = np.nan  # observed (missing is False there) but NaN
    bad_motion = replace(gappy, positions=bad, missing=gappy.missing.copy())
    bad_motion.missing[0, 0] = False
    _raises(ValueError, lambda: fitted.refine(bad_motion), f"{name}.refine with NaN in an observed sample")
    if refiner.requires_fit:
        fewer = replace(
            gappy,
            positions=gappy.positions[:, :-1],
            missing=gappy.missing[:, :-1],
            joint_names=gappy.joint_names[:-1],
            parents=None,
            rotations=None,
            layout_name=None,
        )
        _raises(ValueError, lambda: fitted.refine(fewer), f"{name}.refine on another layout")


# ------------------------------------------------------------------------------------------ retrieval


def check_retrieval_method(method, database: Sequence, queries: Sequence, k: int = 3) -> None:
    """The :class:`~mocapkit.retrieval.base.RetrievalMethod` contract.

    - before ``fit``: ``search`` raises ``NotFittedError``;
    - ``search(queries, k)`` → ``(indices, distances)`` ``[n_queries, k]``: integer indices into the database,
      finite distances, each row sorted nearest first; a query that is in the database finds itself at
      distance 0 first (or tied);
    - ``_state`` / ``_set_state`` (what an index folder saves: plain arrays only) round trip to the same results;
    - bad input: a query with NaN positions raises a ``ValueError``.
    """
    from dataclasses import replace

    name = _name(method)
    _raises(NotFittedError, lambda: method.search(list(queries), k), f"{name}.search before fit")
    fitted = method.fit(list(database))
    assert fitted is method, f"{name}.fit must return the method"
    indices, distances = method.search(list(queries), k)
    indices, distances = np.asarray(indices), np.asarray(distances)
    assert indices.shape == distances.shape == (len(queries), k), f"{name}: shapes {indices.shape}, {distances.shape}"
    assert np.issubdtype(indices.dtype, np.integer) and ((0 <= indices) & (indices < len(database))).all(), (
        f"{name}: indices outside the database"
    )
    assert np.isfinite(distances).all() and (np.diff(distances, axis=1) >= -1e-9).all(), (
        f"{name}: distances not finite or not sorted nearest first"
    )
    own, own_d = method.search([database[0]], 1)
    self_distance = np.asarray(method.distances([database[0]]))[0, 0]
    assert (
        np.isclose(np.asarray(own_d)[0, 0], self_distance)
        and self_distance <= np.asarray(method.distances([database[0]]))[0].min() + 1e-6
    ), f"{name}: a database clip is not nearest to itself"
    state = method._state()
    assert all(isinstance(v, np.ndarray) and v.dtype != object for v in state.values()), (
        f"{name}._state must hold plain arrays (an index loads them with allow_pickle=False)"
    )
    reloaded = clone(method)
    reloaded._set_state({key: np.array(value) for key, value in state.items()})
    again_i, again_d = reloaded.search(list(queries), k)
    assert np.array_equal(np.asarray(again_i), indices) and np.allclose(np.asarray(again_d), distances), (
        f"{name}: search after _state/_set_state differs"
    )
    bad = queries[0].positions.copy()
    bad[:, 0] = np.nan
    _raises(
        ValueError, lambda: method.search([replace(queries[0], positions=bad)], k), f"{name}.search with NaN positions"
    )


# ------------------------------------------------------------------------------------------ synthesis


def check_synthesizer(synthesizer, clips: Sequence, n_frames: int = 20) -> None:
    """The :class:`~mocapkit.synthesis.base.MotionSynthesizer` contract on ASF/AMC ``clips`` of one skeleton.

    - before ``fit``: ``sample`` raises ``NotFittedError``;
    - ``sample(2, n_frames, seed)`` → 2 Motions of ``n_frames`` frames on the training skeleton (same joints and
      fps), finite positions in metres (the bone lengths of the training skeleton), the same again for the same
      seed;
    - bad input: fitting on a single clip, or on a positions-only motion, raises a ``ValueError``.
    """
    from mocapkit.motion.container import Motion

    name = _name(synthesizer)
    _raises(NotFittedError, lambda: synthesizer.sample(2, n_frames, seed=0), f"{name}.sample before fit")
    assert synthesizer.fit(list(clips)) is synthesizer, f"{name}.fit must return the synthesiser"
    variants = synthesizer.sample(2, n_frames, seed=0)
    assert len(variants) == 2, f"{name}: {len(variants)} variants"
    reference = clips[0]
    bones = [(j, p) for j, p in enumerate(reference.parents) if p >= 0]
    length = np.array([np.linalg.norm(reference.positions[0, j] - reference.positions[0, p]) for j, p in bones])
    for motion in variants:
        assert motion.positions.shape == (n_frames, reference.num_joints, 3), f"{name}: {motion.positions.shape}"
        assert motion.joint_names == reference.joint_names and motion.fps == reference.fps, (
            f"{name}: joints or fps differ from the training clips'"
        )
        assert np.isfinite(motion.positions).all(), f"{name}: non-finite positions"
        sampled = np.array([np.linalg.norm(motion.positions[:, j] - motion.positions[:, p], axis=-1) for j, p in bones])
        assert np.allclose(sampled, length[:, None], atol=1e-3), f"{name}: bone lengths differ (not metres?)"
    again = synthesizer.sample(2, n_frames, seed=0)
    assert all(np.allclose(a.positions, b.positions) for a, b in zip(variants, again)), (
        f"{name}: the same seed gave other variants"
    )
    _raises(ValueError, lambda: clone(synthesizer).fit(list(clips[:1])), f"{name}.fit on one clip")
    positions_only = Motion(
        positions=reference.positions, joint_names=reference.joint_names, fps=reference.fps, name="positions_only"
    )
    _raises(
        ValueError,
        lambda: clone(synthesizer).fit([positions_only, *clips[1:]]),
        f"{name}.fit on a positions-only motion",
    )


# ------------------------------------------------------------------------------------------ kinect


def check_kinect_corrector(corrector, pairs: Sequence, folder: str | os.PathLike) -> None:
    """The Kinect corrector contract: ``fit(kinect_clips, mocap_clips, states)``, ``predict(kinect, state)``.

    - before ``fit``: ``predict`` raises ``NotFittedError``, or (a method that learns nothing) gives what it
      gives after ``fit``;
    - ``predict`` of a clip ``[T, 20, 3]`` (metres, y up) → ``[T, 20, 3]`` finite, within 0.5 m of the mocap
      on average (metres in, metres out); a list of clips → a list;
    - ``save(path)`` / ``load(path)`` (where the method has them) round trip to the same predictions;
    - bad input: NaN in the clip, or 19 joints, raises a ``ValueError``.
    """
    name = _name(corrector)
    train, test = pairs[:-1], pairs[-1]
    fit_args = ([p.noisy for p in train], [p.clean for p in train], [p.state for p in train])
    try:
        before = corrector.predict(test.noisy, state=test.state)
    except NotFittedError:
        before = None
    assert corrector.fit(*fit_args) is corrector, f"{name}.fit must return the corrector"
    out = corrector.predict(test.noisy, state=test.state)
    if before is not None:
        assert np.allclose(before, out), f"{name}: predicts before fit, but differently after"
    assert out.shape == test.noisy.shape and np.isfinite(out).all(), f"{name}: output {out.shape}"
    error = np.linalg.norm(out - test.clean, axis=-1).mean()
    assert error < 0.5, f"{name}: mean error {error:.2f} m (metres expected)"
    many = corrector.predict([test.noisy, test.noisy], state=[test.state, test.state])
    assert isinstance(many, list) and len(many) == 2 and np.allclose(many[0], out), f"{name}: a list of clips"
    if hasattr(corrector, "save"):
        path = corrector.save(Path(folder) / f"{name}.model")
        loaded = type(corrector).load(path)
        assert np.allclose(loaded.predict(test.noisy, state=test.state), out, atol=1e-5), (
            f"{name}: predictions after save/load differ"
        )
        assert loaded.get_params() == corrector.get_params() or all(
            _matches(loaded.get_params()[k], v) for k, v in corrector.get_params().items()
        ), f"{name}: parameters after save/load differ"
    bad = test.noisy.copy()
    bad[3, 4] = np.nan
    _raises(ValueError, lambda: corrector.predict(bad, state=test.state), f"{name}.predict with NaN")
    _raises(
        ValueError,
        lambda: corrector.predict(test.noisy[:, :19], state=test.state[:, :19]),
        f"{name}.predict on 19 joints",
    )


# ------------------------------------------------------------------------------------------ depth tracking

#: What a depth sequence may carry besides its depth: :func:`check_depth_estimator` takes each away in turn.
DEPTH_EXTRAS = ("joints", "sensor_joints", "sensor_state", "camera_to_world", "colour", "parts")
_PER_FRAME = ("depth_mm", "colour", "parts", "joints", "sensor_joints", "sensor_state")


def _first_frames(sequence, frames: int, source: str):
    """``sequence`` cut to its first ``frames`` frames (every per-frame array), renamed ``source``."""
    from dataclasses import replace

    cut = {key: getattr(sequence, key)[:frames] for key in _PER_FRAME if getattr(sequence, key) is not None}
    return replace(sequence, source=source, **cut)


def _unless_refused(call, source: str, what: str):
    """``call()``'s result, or None when it raised a ValueError naming ``source``; any other error (or a ValueError
    not naming the file) fails the check."""
    try:
        return call()
    except ValueError as exc:
        assert source in str(exc), f"{what}: the ValueError does not name the file {source!r}: {exc}"
        return None


def check_depth_estimator(estimator, sequences: Sequence, folder: str | os.PathLike) -> None:
    """The depth-tracking contract (:mod:`mocapkit.depth_tracking.base`) on rendered sequences (every field filled;
    the last one is the test sequence, the others are the training performers').

    - before ``fit``: ``predict`` raises ``NotFittedError``, or (a method that learns nothing) gives what it gives
      after ``fit``;
    - ``fit(sequences)`` returns the estimator; ``predict(sequence)`` gives float32 ``[T, 16, 3]``, finite, within
      0.5 m of the ground truth's :data:`~mocapkit.depth_tracking.base.TRACKED_JOINTS` on average (camera
      coordinates, metres in, metres out);
    - ``save(path)`` / ``load(path)`` (where the method has them) round trip to the same predictions;
    - bad input raises a ``ValueError`` naming the sequence's file: a frame with no depth at all, no frames; and
      a sequence without one of :data:`DEPTH_EXTRAS` (at ``predict``; ``joints`` at ``fit``) either gives a valid
      estimate (the method does not need it) or is refused naming the file — never another error.
    """
    from mocapkit.depth_tracking.base import TRACKED_JOINTS, joint_error_mm, tracked_joints

    name = _name(estimator)
    train, test = list(sequences[:-1]), sequences[-1]
    assert train and test.joints is not None, "check_depth_estimator needs ≥ 2 sequences with ground-truth joints"
    try:
        before = estimator.predict(test)
    except NotFittedError:
        before = None
    assert estimator.fit(train) is estimator, f"{name}.fit must return the estimator"
    out = estimator.predict(test)
    if before is not None:
        assert np.allclose(before, out), f"{name}: predicts before fit, but differently after"
    shape = (test.num_frames, len(TRACKED_JOINTS), 3)
    assert isinstance(out, np.ndarray) and out.shape == shape, f"{name}: output {getattr(out, 'shape', out)}"
    assert out.dtype == np.float32 and np.isfinite(out).all(), (
        f"{name}: output {out.dtype}, finite {np.isfinite(out).all()}"
    )
    error = joint_error_mm(out, tracked_joints(test.joints)).mean()
    assert error < 500.0, f"{name}: mean error {error:.0f} mm (metres and camera coordinates expected)"
    if hasattr(estimator, "save"):
        path = estimator.save(Path(folder) / f"{name}.model")
        loaded = type(estimator).load(path)
        assert np.allclose(loaded.predict(test), out, atol=1e-4), f"{name}: predictions after save/load differ"

    # bad input on 3 frames: a method that does not need what was taken away runs through them
    empty = _first_frames(test, 3, "no_depth_in_frame_1.npz")
    empty.depth_mm = empty.depth_mm.copy()
    empty.depth_mm[1] = 0
    none = _first_frames(test, 0, "no_frames.npz")
    for bad, what in ((empty, "a frame with no depth at all"), (none, "no frames")):
        result = _unless_refused(lambda seq=bad: estimator.predict(seq), bad.source, f"{name}.predict, {what}")
        assert result is None, f"{name}.predict: {what} ({bad.source}) raised nothing"
    for key in DEPTH_EXTRAS:
        stripped = _first_frames(test, 3, f"without_{key}.npz")
        setattr(stripped, key, None)
        what = f"{name}.predict on a sequence without {key}"
        result = _unless_refused(lambda seq=stripped: estimator.predict(seq), stripped.source, what)
        if result is not None:  # not needed (colour, say, may still change the estimate): a valid estimate
            assert result.shape == (3, *shape[1:]) and result.dtype == np.float32, f"{what}: output {result.shape}"
            assert np.isfinite(result).all(), f"{what}: non-finite output"
    stripped = _first_frames(train[0], train[0].num_frames, "train_without_joints.npz")
    stripped.joints = None
    _unless_refused(lambda: clone(estimator).fit([stripped, *train[1:]]), stripped.source, f"{name}.fit without joints")


# ------------------------------------------------------------------------------------------ classifiers


def check_sequence_classifier(classifier, sequences: Sequence[np.ndarray], labels: np.ndarray) -> None:
    """A scikit-learn classifier of skeleton sequences (``[T_i, J, 3]`` metres) — recognition and clustering.

    - before ``fit``: ``predict`` raises ``NotFittedError``;
    - ``fit(X, y)`` → ``predict(X)`` ``[n]`` labels among ``classes_`` (= the sorted training labels);
    - bad input: a sequence without its coordinate axis (``[T, J]``) raises a ``ValueError``.
    """
    name = _name(classifier)
    _raises(NotFittedError, lambda: classifier.predict(list(sequences)), f"{name}.predict before fit")
    assert classifier.fit(list(sequences), labels) is classifier, f"{name}.fit must return the classifier"
    predicted = np.asarray(classifier.predict(list(sequences)))
    assert predicted.shape == (len(sequences),), f"{name}: predict shape {predicted.shape}"
    assert np.array_equal(np.asarray(classifier.classes_), np.unique(labels)), f"{name}: classes_"
    assert set(predicted) <= set(np.unique(labels)), f"{name}: predicted labels outside the training labels"
    flat = [np.asarray(s)[..., 0] for s in sequences]
    _raises(ValueError, lambda: classifier.predict(flat), f"{name}.predict on [T, J] sequences")


def check_gait_classifier(classifier, geis: np.ndarray, subjects: np.ndarray) -> None:
    """A scikit-learn classifier of gait energy images ``[N, H, W]`` in [0, 1] with subject labels ``[N]``.

    - before ``fit``: ``predict`` raises ``NotFittedError``;
    - ``fit`` → ``predict`` ``[N]`` subjects among the training ones; the training GEIs are recognised;
    - bad input: NaN in a GEI, or GEIs of another size, raise a ``ValueError``.
    """
    name = _name(classifier)
    _raises(NotFittedError, lambda: classifier.predict(geis), f"{name}.predict before fit")
    assert classifier.fit(geis, subjects) is classifier, f"{name}.fit must return the classifier"
    predicted = np.asarray(classifier.predict(geis))
    assert predicted.shape == (len(geis),) and set(predicted) <= set(subjects), f"{name}: predict"
    assert (predicted == subjects).mean() > 0.9, f"{name}: the training GEIs are not recognised"
    bad = geis.copy()
    bad[0, 0, 0] = np.nan
    _raises(ValueError, lambda: classifier.predict(bad), f"{name}.predict with NaN")
    _raises(ValueError, lambda: classifier.predict(geis[:, :-1]), f"{name}.predict on GEIs of another size")
