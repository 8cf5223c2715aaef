"""NMFLayer (non-negative codes, monotone MU descent, one-step gradient, safety, graph option, ONNX parity)
and the end-to-end model built on it, mocapkit.models.clip_bow (shapes, padding masks, export, training)."""

import warnings

import lightning as L
import numpy as np
import onnxruntime as ort
import pytest
import torch
from torch.utils.data import DataLoader, TensorDataset

from mocapkit.models.clip_bow import ClipNMFBagOfWords, clip_nmf_bow
from mocapkit.models.nmf_layer import NMFLayer
from mocapkit.recognition.export import example_skeletons, export_onnx
from mocapkit.recognition.module import ActionRecognitionModule


def _data(batch=3, n=12, d=8, k=4, seed=0):
    """Exactly non-negative low-rank data plus a little positive noise."""
    g = torch.Generator().manual_seed(seed)
    codes = torch.rand(batch, n, k, generator=g)
    atoms = torch.rand(k, d, generator=g)
    return codes @ atoms + 0.01 * torch.rand(batch, n, d, generator=g)


def _graph_size(tensor: torch.Tensor) -> int:
    """Number of autograd nodes reachable from ``tensor.grad_fn``."""
    seen, stack = set(), [tensor.grad_fn]
    while stack:
        node = stack.pop()
        if node is None or node in seen:
            continue
        seen.add(node)
        stack.extend(next_fn for next_fn, _ in node.next_functions)
    return len(seen)


def test_codes_are_non_negative_with_expected_shape():
    layer = NMFLayer(8, 5, n_iter=7)
    codes = layer(_data() - 0.05)  # some negative inputs: clamped to zero
    assert codes.shape == (3, 12, 5)
    assert (codes >= 0).all() and torch.isfinite(codes).all()


def test_multiplicative_updates_decrease_reconstruction_error_monotonically():
    torch.manual_seed(0)
    layer = NMFLayer(8, 4, n_iter=30)
    errors = np.array(layer.reconstruction_errors(_data()))
    assert len(errors) == 31
    assert (np.diff(errors) <= 1e-6 * errors[0]).all(), errors
    assert errors[-1] < 0.5 * errors[0]


def test_reconstruction_approximates_input():
    torch.manual_seed(0)
    x = _data()
    layer = NMFLayer(8, 4, n_iter=50)
    with torch.no_grad():
        # dictionary = the true atoms: MU on the codes must fit x almost exactly
        g = torch.Generator().manual_seed(0)
        torch.rand(3, 12, 4, generator=g)
        layer.set_dictionary(torch.rand(4, 8, generator=g))
        rel = ((layer.reconstruction(x) - x).norm() / x.norm()).item()
    assert rel < 0.1


def test_one_step_gradient_keeps_only_the_last_step_in_the_graph():
    torch.manual_seed(0)
    x = _data().requires_grad_(True)
    sizes = {}
    for n_iter in (2, 10):
        for one_step in (True, False):
            layer = NMFLayer(8, 4, n_iter=n_iter, one_step_grad=one_step)
            sizes[n_iter, one_step] = _graph_size(layer(x).sum())
    # one-step: graph independent of n_iter; full unrolling: grows with n_iter
    assert sizes[2, True] == sizes[10, True]
    assert sizes[10, False] > sizes[2, False] >= sizes[2, True]


def test_one_step_gradient_equals_gradient_of_last_step_from_detached_codes():
    torch.manual_seed(0)
    layer = NMFLayer(8, 4, n_iter=6, one_step_grad=True)
    x = _data().requires_grad_(True)
    layer(x).square().sum().backward()
    grad_d, grad_x = layer.raw_dictionary.grad.clone(), x.grad.clone()
    assert grad_d.abs().sum() > 0 and grad_x.abs().sum() > 0

    layer.zero_grad()
    x2 = x.detach().clone().requires_grad_(True)
    with torch.no_grad():
        codes, d = layer.initial_codes(x2), layer.dictionary
        for _ in range(5):
            codes, _ = layer.step(x2, codes, d)
    last, _ = layer.step(x2, codes.detach(), layer.dictionary)
    last.square().sum().backward()
    torch.testing.assert_close(layer.raw_dictionary.grad, grad_d)
    torch.testing.assert_close(x2.grad, grad_x)


def test_all_zero_input_gives_finite_zero_codes_and_gradients():
    layer = NMFLayer(8, 4, n_iter=5, graph_reg=1.0)
    x = torch.zeros(2, 6, 8, requires_grad=True)
    codes = layer(x)
    assert torch.isfinite(codes).all() and (codes == 0).all()
    codes.sum().backward()
    assert torch.isfinite(x.grad).all() and torch.isfinite(layer.raw_dictionary.grad).all()


def test_graph_regularisation_runs_and_smooths_codes_of_neighbours():
    torch.manual_seed(0)
    x = _data(batch=2, n=10)
    plain = NMFLayer(8, 4, n_iter=20)
    graph = NMFLayer(8, 4, n_iter=20, graph_reg=5.0, n_neighbors=3)
    graph.load_state_dict(plain.state_dict())
    adjacency = graph.knn_graph(x)
    assert adjacency.shape == (2, 10, 10)
    assert torch.equal(adjacency, adjacency.transpose(1, 2)) and adjacency.diagonal(dim1=1, dim2=2).eq(0).all()
    assert (adjacency.sum(-1) >= 3).all()
    c_plain, c_graph = plain(x), graph(x)
    assert (c_graph >= 0).all() and not torch.allclose(c_plain, c_graph)

    def roughness(codes):  # Σ_ij S_ij ||c_i − c_j||² on the normalised codes
        unit = codes / codes.sum(-1, keepdim=True)
        return (adjacency * torch.cdist(unit, unit) ** 2).sum()

    assert roughness(c_graph) < roughness(c_plain)


def test_mask_makes_padding_items_irrelevant():
    torch.manual_seed(0)
    layer = NMFLayer(8, 4, n_iter=8, graph_reg=0.5, n_neighbors=2)
    x = _data(batch=1, n=5)
    padded = torch.cat([x, torch.rand(1, 4, 8)], dim=1)
    mask = torch.tensor([[True] * 5 + [False] * 4])
    torch.testing.assert_close(layer(padded, mask)[:, :5], layer(x))
    assert (layer(padded, mask)[:, 5:] == 0).all()


def test_local_dictionary_update_option_runs():
    layer = NMFLayer(8, 4, n_iter=5, update_dictionary=True)
    x = _data()
    codes = layer(x)
    codes.sum().backward()
    assert (codes >= 0).all() and torch.isfinite(layer.raw_dictionary.grad).all()


def test_bad_arguments_name_the_parameter():
    with pytest.raises(ValueError, match="n_iter"):
        NMFLayer(8, 4, n_iter=0)
    with pytest.raises(ValueError, match="graph_reg"):
        NMFLayer(8, 4, graph_reg=-1.0)
    with pytest.raises(ValueError, match=r"x \[batch, n, 8\]"):
        NMFLayer(8, 4)(torch.rand(3, 7))


def test_onnx_export_with_dynamic_batch_and_items_matches_torch(tmp_path):
    """One export covers both paths: the MU steps and the in-layer kNN graph (k capped at n − 1 for n = 2)."""
    torch.manual_seed(0)
    layer = NMFLayer(8, 4, n_iter=4, graph_reg=0.5, n_neighbors=3).eval()
    batch, items = torch.export.Dim("batch", min=1, max=1024), torch.export.Dim("items", min=2, max=4096)
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        program = torch.onnx.export(
            layer,
            (_data(2, 9),),
            None,
            input_names=["x"],
            output_names=["codes"],
            dynamic_shapes={"x": {0: batch, 1: items}},
            dynamo=True,
            optimize=False,
        )
    path = tmp_path / "nmf.onnx"
    program.save(str(path))
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    for b, n in ((3, 17), (1, 2), (5, 4)):
        x = _data(b, n, seed=b)
        with torch.no_grad():
            expected = layer(x).numpy()
        got = session.run(["codes"], {"x": x.numpy()})[0]
        assert got.shape == (b, n, 4)
        np.testing.assert_allclose(got, expected, atol=1e-5, rtol=1e-4)


# ---------------------------------------------------------------- the end-to-end model (clip_bow)


def _model(**kwargs) -> ClipNMFBagOfWords:
    torch.manual_seed(0)
    options = dict(n_components=16, encoder_hidden=32, n_iter=5, frames_per_clip=5)
    options.update(kwargs)
    return clip_nmf_bow(num_classes=6, layout="msr20", **options).eval()


def test_forward_shapes_and_soft_bag_of_words_sums_to_one():
    model = _model()
    x = example_skeletons(3, 50, bodies=2, joints=20)
    assert model.layout.name == "msr20"
    assert model(x).shape == (3, 6)
    words, valid = model.soft_words(x)
    assert words.shape == (3, -(-50 // 15), 16) and valid.shape == (3, 4)
    bag = model.bag_of_words(x)
    torch.testing.assert_close(bag.sum(1), torch.ones(3))
    assert (bag >= 0).all()


def test_sequences_shorter_than_a_window_and_wrong_shapes():
    model = _model()
    assert torch.isfinite(model(example_skeletons(2, 2, bodies=1, joints=20))).all()
    with pytest.raises(ValueError, match=r"\[B, M, T, 20, 3\]"):
        model(torch.zeros(2, 1, 30, 25, 3))


@pytest.mark.parametrize("graph_reg", [0.0, 0.5])
def test_zero_padded_batch_equals_each_sample_alone(graph_reg):
    model = _model(graph_reg=graph_reg)
    g = torch.Generator().manual_seed(1)
    lengths = [20, 47, 90]
    samples = [
        torch.randn(1, 1, n, 20, 3, generator=g).cumsum(2) * 0.02 + torch.tensor([0.0, 0.0, 2.5]) for n in lengths
    ]
    batch = torch.zeros(3, 1, 90, 20, 3)
    for i, s in enumerate(samples):
        batch[i, :, : s.shape[2]] = s[0]
    with torch.no_grad():
        together = model(batch)
        alone = torch.cat([model(s) for s in samples])
    torch.testing.assert_close(together, alone, atol=1e-5, rtol=1e-4)


def test_body_zero_is_used():
    model = _model()
    x = example_skeletons(2, 40, bodies=2, joints=20)
    y = x.clone()
    y[:, 1] = torch.randn_like(y[:, 1])
    with torch.no_grad():
        torch.testing.assert_close(model(x), model(y))


def test_exports_through_export_onnx_with_parity(tmp_path):
    report = export_onnx(_model(graph_reg=0.5), tmp_path / "clip_bow.onnx", class_names=[f"c{i}" for i in range(6)])
    assert report["same_top1"] and report["max_abs_diff"] < 1e-4
    assert report["layout"] == "msr20"


def _synthetic_actions(n_per_class: int, classes: int, frames: int, seed: int):
    """Each class moves one joint group along its own direction; one body with small per-sample variation,
    random position, length and noise."""
    body = torch.randn(1, 20, 3, generator=torch.Generator().manual_seed(123)) * 0.2
    g = torch.Generator().manual_seed(seed)
    xs, ys = [], []
    for c in range(classes):
        direction = torch.zeros(3)
        direction[c % 3] = 1.0 if c < 3 else -1.0
        joints = [9, 10, 11, 12] if c % 2 == 0 else [13, 14, 15, 16]
        for _ in range(n_per_class):
            pose = (
                body
                + torch.randn(1, 20, 3, generator=g) * 0.02
                + torch.randn(1, 1, 3, generator=g) * 0.3
                + torch.tensor([0.0, 0.0, 2.5])
            )
            t = torch.linspace(0, 1, frames)[:, None]
            seq = pose.repeat(frames, 1, 1)
            seq[:, joints] += (0.4 * t * direction)[:, None, :]
            seq += torch.randn(frames, 20, 3, generator=g) * 0.01
            length = int(torch.randint(frames // 2, frames + 1, (1,), generator=g))
            seq[length:] = 0.0
            xs.append(seq[None])
            ys.append(c)
    return torch.stack(xs), torch.tensor(ys)


@pytest.mark.slow
def test_trains_through_action_recognition_module_above_chance():
    L.seed_everything(0)
    classes = 6
    x_train, y_train = _synthetic_actions(12, classes, 45, seed=0)
    x_test, y_test = _synthetic_actions(6, classes, 45, seed=1)
    model_cfg = {
        "_target_": "mocapkit.models.clip_bow.clip_nmf_bow",
        "layout": "msr20",
        "window": 20,
        "stride": 10,
        "frames_per_clip": 5,
        "n_components": 16,
        "n_iter": 5,
        "encoder_hidden": 32,
    }
    module = ActionRecognitionModule(
        model=model_cfg, num_classes=classes, optimizer={"_target_": "torch.optim.AdamW", "_partial_": True, "lr": 1e-2}
    )

    def loader(x, y, shuffle):
        data = TensorDataset(x, y)
        return DataLoader(
            data,
            batch_size=12,
            shuffle=shuffle,
            collate_fn=lambda b: {
                "skeletons": torch.stack([s for s, _ in b]),
                "labels": torch.stack([t for _, t in b]),
            },
        )

    trainer = L.Trainer(
        max_epochs=25,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
    )
    trainer.fit(module, loader(x_train, y_train, True))
    module.eval()
    with torch.no_grad():
        accuracy = (module(x_test).argmax(1) == y_test).float().mean().item()
    assert accuracy > 2.0 / classes, accuracy  # chance is 1/6
    assert np.isfinite(module.model.nmf.dictionary.detach().numpy()).all()
