"""The ST-GCN-family graph network: adjacency from a layout, shapes, padding invariance, learning, ONNX."""

import numpy as np
import pytest
import torch

from mocapkit.models.stgcn import STGCN, spatial_adjacency, stgcn
from mocapkit.motion.layouts import CMU31, MSR20, NTU25
from tests.shared_data import NTU_SAMPLES, needs


@pytest.mark.parametrize("layout", [MSR20, NTU25, CMU31], ids=lambda l: l.name)
def test_adjacency_is_symmetric_normalised_and_matches_the_bones(layout):
    a = spatial_adjacency(layout)
    j = layout.num_joints
    assert a.shape == (3, j, j)
    full = a.sum(0)
    torch.testing.assert_close(full, full.T)
    torch.testing.assert_close(a[1], a[2].T)
    edges = {tuple(sorted(b)) for b in layout.bones}
    degree = torch.ones(j)
    for c, p in layout.bones:
        degree[c] += 1
        degree[p] += 1
    expected = torch.diag(1.0 / degree)
    for c, p in layout.bones:
        expected[c, p] = expected[p, c] = 1.0 / torch.sqrt(degree[c] * degree[p])
    torch.testing.assert_close(full, expected)
    off = {(i, k) for i, k in zip(*np.nonzero(full.numpy())) if i < k}
    assert off == edges
    # inward: each joint gathers from its parent; outward: from its children
    for c, p in layout.bones:
        assert a[1, c, p] > 0 and a[2, p, c] > 0 and a[1, p, c] == 0
    assert torch.equal(a[0], torch.diag(torch.diagonal(a[0])))
    # the symmetric normalisation: the largest eigenvalue of D^-1/2 (A+I) D^-1/2 is 1
    assert torch.linalg.eigvalsh(full).max() == pytest.approx(1.0, abs=1e-5)


@pytest.mark.parametrize("layout,bodies", [("msr20", 1), ("ntu25", 2), ("cmu31", 1)])
def test_forward_shapes(layout, bodies):
    model = stgcn(7, layout=layout, streams=["joint", "velocity", "bone"], scale=True)
    x = torch.randn(3, bodies, 30, model.num_joints, 3)
    assert model(x).shape == (3, 7)
    assert STGCN(MSR20, 4)(torch.randn(2, 1, 12, 20, 3)).shape == (2, 4)  # a SkeletonLayout works too
    with pytest.raises(ValueError, match="unknown skeleton layout"):
        stgcn(3, layout="kinect15")


@pytest.mark.parametrize("temporal,topology", [("conv", "shared"), ("multiscale", "shared"), ("conv", "channelwise")])
def test_zero_padded_frames_and_absent_bodies_do_not_change_the_output(temporal, topology):
    torch.manual_seed(0)
    model = stgcn(
        5,
        layout="ntu25",
        streams=["joint", "velocity", "bone"],
        scale=True,
        dropout=0.2,
        temporal=temporal,
        topology=topology,
    ).eval()
    for m in model.modules():  # BN statistics away from 0 / 1, so a leak of padding would show
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-1, 1)
            m.bias.data.uniform_(-1, 1)
        if hasattr(m, "alpha"):  # the channel-wise refinement switched on
            m.alpha.data.fill_(0.5)
    x = torch.randn(4, 2, 37, 25, 3) * 0.3 + torch.tensor([0.0, 0.0, 3.0])
    x[:, 1] = 0.0  # second body absent
    x[2, :, 21:] = 0.0  # a shorter sample
    with torch.no_grad():
        ref = model(x)
        padded = model(torch.cat([x, torch.zeros(4, 2, 26, 25, 3)], dim=2))
        one_body = model(x[:, :1])
        alone = model(x[2:3, :, :21])
    torch.testing.assert_close(padded, ref, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(one_body, ref, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(alone, ref[2:3], atol=1e-5, rtol=1e-5)


def test_multiscale_temporal_unit_shapes_receptive_field_and_bad_settings():
    from mocapkit.models.stgcn import MultiScaleTemporalConv

    unit = MultiScaleTemporalConv(8, 32, stride=2).eval()
    widths = [branch[0].out_channels for branch in unit.squeeze]
    assert widths == [7, 5, 5, 5, 5, 5] and sum(widths) == 32
    x = torch.zeros(1, 8, 21, 4)
    mask = torch.ones(1, 1, 21, 1)
    assert unit(x, mask).shape == (1, 32, 11, 4)
    # the widest branch (dilation 4) reaches 4 frames each side and no farther (10 channels a branch, so the
    # ReLU before the step cannot hide the change from a whole branch)
    torch.manual_seed(0)
    unit = MultiScaleTemporalConv(4, 60).eval()
    x = torch.randn(1, 4, 21, 3)
    base = unit(x, mask)
    moved = x.clone()
    moved[:, :, 10] += 1.0
    changed = (unit(moved, mask) - base).abs().amax(dim=(0, 1, 3)) > 1e-6
    assert changed.nonzero().flatten().tolist() == list(range(6, 15))
    with pytest.raises(ValueError, match="at least 6 channels"):
        MultiScaleTemporalConv(4, 5)
    with pytest.raises(ValueError, match="unknown temporal unit 'tcn'"):
        stgcn(3, layout="msr20", temporal="tcn")


def test_channelwise_topology_starts_from_the_shared_graph_and_then_depends_on_the_sample():
    from mocapkit.models.stgcn import GraphConv

    torch.manual_seed(0)
    a = spatial_adjacency(MSR20)
    shared = GraphConv(6, 16, a)
    refined = GraphConv(6, 16, a, topology="channelwise")
    refined.load_state_dict(shared.state_dict(), strict=False)
    x = torch.randn(3, 6, 10, 20)
    torch.testing.assert_close(refined(x), shared(x))  # alpha = 0: CTR-GCN's starting point
    assert refined.relation_channels == 8
    refined.alpha.data.fill_(1.0)
    out = refined(x)
    assert not torch.allclose(out, shared(x), atol=1e-3)
    # the refinement is per sample: a sample's output does not depend on the rest of the batch
    torch.testing.assert_close(refined(x[1:2]), out[1:2])
    # and per channel: the same input channels, different gathering per output channel
    q = refined.relation_out(torch.tanh(torch.randn(1, 24, 20, 1) - torch.randn(1, 24, 1, 20)))
    assert q.view(3, 16, 20, 20).std(dim=1).mean() > 1e-3
    with pytest.raises(ValueError, match="unknown graph topology 'ctr'"):
        GraphConv(6, 16, a, topology="ctr")


def test_centering_makes_it_translation_invariant():
    torch.manual_seed(1)
    model = stgcn(3, layout="msr20", scale=True).eval()
    x = torch.randn(2, 1, 16, 20, 3)
    with torch.no_grad():
        torch.testing.assert_close(model(x + torch.tensor([0.5, -0.2, 2.0])), model(x), atol=1e-4, rtol=1e-4)


def test_it_learns_a_toy_two_class_problem():
    """Class 0 raises the right wrist, class 1 the left one; random lengths, zero padding."""
    torch.manual_seed(0)
    n, t = 64, 20
    x = torch.randn(n, 1, t, 20, 3) * 0.02 + torch.tensor([0.0, 0.0, 2.5])
    labels = torch.arange(n) % 2
    ramp = torch.linspace(0, 0.5, t)
    for i in range(n):
        wrist = MSR20.index("WristRight") if labels[i] == 0 else MSR20.index("WristLeft")
        x[i, 0, :, wrist, 1] += ramp
        x[i, 0, int(torch.randint(12, t + 1, ())) :] = 0.0
    model = stgcn(2, layout="msr20", channels=[32, 32], strides=[1, 2], kernel_size=3)
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    for _ in range(40):
        loss = torch.nn.functional.cross_entropy(model(x), labels)
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()
    with torch.no_grad():
        assert (model(x).argmax(1) == labels).float().mean() > 0.95


@pytest.mark.parametrize("temporal,topology", [("conv", "shared"), ("multiscale", "channelwise")])
def test_onnx_export_on_msr20_one_body(tmp_path, temporal, topology):
    """`mocapkit export`'s function takes the joint count from ``model.layout``; bodies and frames are dynamic."""
    from mocapkit.recognition.export import export_onnx

    model = stgcn(
        4,
        layout="msr20",
        streams=["joint", "velocity", "bone"],
        scale=True,
        channels=[16, 16],
        strides=[2, 1],
        temporal=temporal,
        topology=topology,
    )
    for m in model.modules():
        if hasattr(m, "alpha"):
            m.alpha.data.fill_(0.5)
    report = export_onnx(
        model, tmp_path / "gcn.onnx", class_names=list("abcd"), trace_shape=(2, 32), check_shape=(3, 41)
    )
    assert report["layout"] == "msr20" and report["traced_shape"][3] == 20
    assert report["max_abs_diff"] < 1e-4 and report["same_top1"]


def test_multi_stream_ensemble_trains_each_member_and_averages_at_inference(tmp_path):
    from mocapkit.models.stgcn import stgcn_ensemble
    from mocapkit.recognition.module import ActionRecognitionModule

    torch.manual_seed(0)
    net = stgcn_ensemble(
        5, layout="msr20", streams=[["joint"], ["bone"], ["bone_velocity"]], channels=[8, 8], strides=[1, 1]
    )
    x = torch.randn(4, 1, 12, 20, 3)
    net.train()
    members = net(x)
    assert members.shape == (3, 4, 5)
    net.eval()
    torch.testing.assert_close(net(x), torch.stack([m(x) for m in net.members]).mean(0))
    # velocity of the bones: zero for a skeleton translated rigidly frame by frame
    still = torch.randn(1, 1, 1, 20, 3).repeat(1, 1, 6, 1, 1) + torch.arange(6.0).view(1, 1, 6, 1, 1)
    member = net.members[2]
    assert member.features(still, still.abs().sum((-1, -2)) > 0).abs().max() < 1e-5

    spec = {
        "_target_": "mocapkit.models.stgcn.stgcn_ensemble",
        "layout": "msr20",
        "channels": [8, 8],
        "strides": [1, 1],
        "streams": [["joint"], ["bone"]],
    }
    module = ActionRecognitionModule(spec, {"_target_": "torch.optim.SGD", "_partial_": True, "lr": 0.1}, num_classes=5)
    module.train()
    batch = {"skeletons": x, "labels": torch.tensor([0, 1, 2, 3])}
    loss = module._step(batch, "train")
    each = [torch.nn.functional.cross_entropy(m(x), batch["labels"]) for m in module.model.members]
    torch.testing.assert_close(loss, each[0] + each[1])  # each member on its own loss


@needs(NTU_SAMPLES)
def test_predict_samples_frames_as_training_did(tmp_path):
    """The exported model stores data.max_frames; `mocapkit predict` subsamples a longer file to it, uniformly."""
    import onnxruntime as ort

    from mocapkit.models.stgcn import stgcn_ensemble
    from mocapkit.motion.frames import uniform_frame_indices
    from mocapkit.recognition.export import export_onnx
    from mocapkit.recognition.predict import model_input, predict_files

    torch.manual_seed(0)
    model = stgcn_ensemble(3, layout="ntu25", streams=[["joint"], ["bone"]], channels=[8, 8], strides=[1, 1])
    out = tmp_path / "ens.onnx"
    report = export_onnx(
        model, out, class_names=["a", "b", "c"], trace_shape=(2, 16), check_shape=(3, 21), max_frames=8
    )
    assert report["layout"] == "ntu25" and report["same_top1"]
    sample = min(NTU_SAMPLES.glob("*.skeleton"))
    x = model_input(sample, "ntu25").astype(np.float32)  # [1, 2, T, 25, 3]
    assert x.shape[2] > 8
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    sampled = session.run(None, {"skeletons": x[:, :, uniform_frame_indices(x.shape[2], 8)]})[0][0]
    probs = np.exp(sampled - sampled.max()) / np.exp(sampled - sampled.max()).sum()
    (result,) = predict_files(out, [sample], top=3)
    top = dict(result["top"])
    np.testing.assert_allclose([top[n] for n in "abc"], probs, rtol=1e-5)
    full = session.run(None, {"skeletons": x})[0][0]
    assert not np.allclose(full, sampled)  # all frames would have given another answer
