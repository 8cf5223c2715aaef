"""Issue 11's refiner networks retrained as Kinect correctors (mocapkit/kinect/learned.py), on the
synthetic clips with a known pose-dependent Kinect error of tests/test_kinect_reconstruction.py."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

from mocapkit.kinect.learned import LearnedKinectCorrector
from tests.kinect.test_kinect_reconstruction import _error, paired_clips

SMALL = {"network": {"hidden": 32}, "window": 32, "steps": 150, "batch_size": 16, "lr": 3e-3}


@pytest.fixture(scope="module")
def data():
    return paired_clips(0, 8), paired_clips(1, 3)  # training takes and separate held-out takes


@pytest.fixture(scope="module")
def fitted(data):
    (ktr, mtr), _ = data
    return LearnedKinectCorrector(**SMALL, random_state=0).fit(ktr, mtr)


def test_corrector_learns_the_kinect_error_and_cuts_it_on_held_out_clips(fitted, data):
    _, (kte, mte) = data
    assert len(fitted.loss_curve_) == SMALL["steps"]
    assert fitted.loss_curve_[-20:].mean() < 0.75 * fitted.loss_curve_[:5].mean()
    corrected = fitted.predict(kte)
    assert [c.shape for c in corrected] == [k.shape for k in kte]
    assert _error(corrected, mte) < 0.8 * _error(kte, mte)


def test_long_clips_run_in_blended_windows_and_short_clips_train_padded(fitted, data):
    _, (kte, mte) = data
    long = np.concatenate(kte)  # 360 frames: several 64-frame inference windows
    out = fitted.predict(long)
    assert out.shape == long.shape and np.isfinite(out).all()
    # per-window normalisation: a window sees the clip's own part only, so the blended take is as good as the clips
    assert joint_error(out, np.concatenate(mte)) < 0.85 * joint_error(long, np.concatenate(mte))
    (ktr, mtr), _ = data
    short = LearnedKinectCorrector(**{**SMALL, "steps": 2}).fit([k[:20] for k in ktr[:3]], [m[:20] for m in mtr[:3]])
    assert short.n_windows_ == 3 and short.predict(ktr[0][:10]).shape == (10, 20, 3)


def joint_error(a, b):
    return float(np.linalg.norm(a - b, axis=-1).mean())


def test_same_random_state_same_corrector(data):
    (ktr, mtr), (kte, _) = data
    quick = {**SMALL, "steps": 5}
    a = LearnedKinectCorrector(**quick, random_state=3).fit(ktr[:3], mtr[:3])
    b = clone(a).fit(ktr[:3], mtr[:3])
    np.testing.assert_array_equal(a.predict(kte[0]), b.predict(kte[0]))
    c = LearnedKinectCorrector(**quick, random_state=4).fit(ktr[:3], mtr[:3])
    assert not np.array_equal(a.predict(kte[0]), c.predict(kte[0]))


def test_transformer_architecture_trains_and_predicts(data):
    (ktr, mtr), (kte, _) = data
    model = LearnedKinectCorrector(
        architecture="transformer", network={"dim": 32, "layers": 1, "ff": 64}, window=32, steps=3, batch_size=8
    ).fit(ktr[:2], mtr[:2])
    assert model.predict(kte[1]).shape == kte[1].shape


def test_bad_parameters_inputs_and_not_fitted(data):
    (ktr, mtr), _ = data
    with pytest.raises(NotFittedError):
        LearnedKinectCorrector().predict(ktr[0])
    for params, message in (
        ({"architecture": "lstm"}, "architecture"),
        ({"network": "big"}, "network"),
        ({"window": 2}, "window"),
        ({"steps": 0}, "steps"),
    ):
        with pytest.raises(ValueError, match=message):
            LearnedKinectCorrector(**params).fit(ktr[:2], mtr[:2])
    bad = ktr[0].copy()
    bad[4, 7] = np.nan
    with pytest.raises(ValueError, match=r"kinect_clips\[0\].*frame 4, joint 7 \(l_hand\)"):
        LearnedKinectCorrector(**SMALL).fit([bad], [mtr[0]])
    with pytest.raises(ValueError, match="has 120 frames but"):
        LearnedKinectCorrector(**SMALL).fit([ktr[0]], [mtr[0][:50]])


def test_saved_corrector_predicts_exactly_as_the_fitted_one_and_bad_files_are_named(fitted, data, tmp_path):
    _, (kte, _) = data
    path = fitted.save(tmp_path / "sub" / "corrector.pt")
    loaded = LearnedKinectCorrector.load(path)
    assert loaded.get_params() == fitted.get_params() and loaded.n_windows_ == fitted.n_windows_
    np.testing.assert_array_equal(loaded.predict(kte[0]), fitted.predict(kte[0]))
    not_a_model = tmp_path / "notes.pt"
    not_a_model.write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="notes.pt: not a Kinect corrector"):
        LearnedKinectCorrector.load(not_a_model)
    import torch

    other = tmp_path / "other.pt"
    torch.save({"format": "something-else", "params": {}}, other)
    with pytest.raises(ValueError, match="other.pt.*format 'something-else'"):
        LearnedKinectCorrector.load(other)


def test_untracked_joints_can_go_to_the_network_as_missing(data):
    (ktr, mtr), (kte, _) = data
    states = [np.full(k.shape[:2], 2, dtype=np.int8) for k in ktr]
    for s in states:
        s[10:20, 7] = 1  # the left hand inferred for ten frames
    quick = {**SMALL, "steps": 5}
    model = LearnedKinectCorrector(**quick, untracked_as_missing=True).fit(ktr[:3], mtr[:3], states[:3])
    test_state = np.full(kte[0].shape[:2], 2, dtype=np.int8)
    test_state[30:40, 7] = 0
    far = kte[0].copy()
    far[30:40, 7] += 5.0  # a wild sample where the sensor lost the joint
    # what the network returns does not depend on the value at an entry it gets as missing
    np.testing.assert_allclose(model.predict(far, state=test_state), model.predict(kte[0], state=test_state), atol=1e-5)
    assert not np.allclose(model.predict(far), model.predict(kte[0]), atol=1e-3)  # without the state it does
    plain = LearnedKinectCorrector(**quick).fit(ktr[:3], mtr[:3], states[:3])
    np.testing.assert_array_equal(plain.predict(far, state=test_state), plain.predict(far))
    with pytest.raises(ValueError, match="untracked_as_missing"):
        LearnedKinectCorrector(untracked_as_missing="yes").fit(ktr[:2], mtr[:2])
    with pytest.raises(ValueError, match=r"state\[0\]: expected a \[T, 20\] tracking-state array with T = 120"):
        model.predict(kte[0], state=test_state[:5])


def test_onnx_export_corrects_as_the_corrector_does_and_bad_files_are_named(fitted, data, tmp_path):
    from mocapkit.kinect.learned import OnnxKinectCorrector

    _, (kte, _) = data
    figures = fitted.export_onnx(tmp_path / "corrector.onnx")
    assert figures["max_abs_diff"] < 1e-4 and figures["checked_shape"] != figures["traced_shape"]
    exported = OnnxKinectCorrector(figures["onnx"]).fit()
    assert exported.corrector_["window"] == SMALL["window"] and not exported.corrector_["untracked_as_missing"]
    long = np.concatenate(kte)  # 360 frames: windows blended as in predict
    np.testing.assert_allclose(exported.predict(long), fitted.predict(long), atol=1e-4)
    assert [c.shape for c in exported.predict(kte)] == [k.shape for k in kte]
    # the prediction windows can be set as on the corrector
    np.testing.assert_allclose(
        exported.set_params(inference_window=40, overlap=8).predict(long),
        fitted.set_params(inference_window=40, overlap=8).predict(long),
        atol=1e-4,
    )
    fitted.set_params(inference_window=None, overlap=None)
    with pytest.raises(NotFittedError):
        OnnxKinectCorrector(figures["onnx"]).predict(long)
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="garbage.onnx: onnxruntime cannot load it"):
        OnnxKinectCorrector(garbage).fit()
    import onnx
    from onnx import TensorProto, helper

    identity = helper.make_model(
        helper.make_graph(
            [helper.make_node("Identity", ["positions"], ["refined"])],
            "g",
            [helper.make_tensor_value_info("positions", TensorProto.FLOAT, None)],
            [helper.make_tensor_value_info("refined", TensorProto.FLOAT, None)],
        )
    )
    onnx.save(identity, tmp_path / "identity.onnx")
    with pytest.raises(ValueError, match="identity.onnx: not a Kinect corrector export"):
        OnnxKinectCorrector(tmp_path / "identity.onnx").fit()
    with pytest.raises(ValueError, match="absent.onnx: no such ONNX file"):
        OnnxKinectCorrector(tmp_path / "absent.onnx").fit()


def test_onnx_export_keeps_the_tracking_state_rule(data, tmp_path):
    from mocapkit.kinect.learned import OnnxKinectCorrector

    (ktr, mtr), (kte, _) = data
    model = LearnedKinectCorrector(**{**SMALL, "steps": 3}, untracked_as_missing=True).fit(ktr[:2], mtr[:2])
    exported = OnnxKinectCorrector(model.export_onnx(tmp_path / "untracked.onnx")["onnx"]).fit()
    state = np.full(kte[0].shape[:2], 2, dtype=np.int8)
    state[30:40, 7] = 0
    far = kte[0].copy()
    far[30:40, 7] += 5.0
    np.testing.assert_allclose(exported.predict(far, state=state), model.predict(far, state=state), atol=1e-4)
    np.testing.assert_allclose(exported.predict(far, state=state), exported.predict(kte[0], state=state), atol=1e-4)


def test_the_trainer_parameter_reaches_the_lightning_trainer(data, monkeypatch):
    import mocapkit.train.training as training

    (ktr, mtr), _ = data
    built, real = [], training.build_trainer
    monkeypatch.setattr(training, "build_trainer", lambda *a, **kw: built.append(real(*a, **kw)) or built[-1])
    quick = {**SMALL, "steps": 50}
    model = LearnedKinectCorrector(**quick, trainer={"max_steps": 2, "precision": "bf16-mixed"}).fit(ktr[:2], mtr[:2])
    assert len(built) == 1 and built[0].max_steps == 2 and built[0].precision == "bf16-mixed"
    assert built[0].logger is None and len(model.loss_curve_) == 2
    plain = LearnedKinectCorrector(**{**quick, "steps": 3}).fit(ktr[:2], mtr[:2])
    assert built[1].max_steps == 3 and built[1].precision == "32-true" and len(plain.loss_curve_) == 3
    monkeypatch.undo()
    with pytest.raises(ValueError, match=r"\['devcies'\] are not arguments of lightning.Trainer"):
        LearnedKinectCorrector(**quick, trainer={"devcies": 2}).fit(ktr[:2], mtr[:2])
    with pytest.raises(ValueError, match="trainer must be a dict"):
        LearnedKinectCorrector(**quick, trainer="gpu").fit(ktr[:2], mtr[:2])
