"""Learned motion embeddings for retrieval: encoder, losses, data module, `mocapkit train|eval|export`, and
:class:`~mocapkit.retrieval.embedding.EmbeddingRetrieval` (checkpoint and ONNX, FAISS flat / HNSW, state).

The end-to-end run trains one tiny epoch on a synthetic HDM05-format folder (the generator's output renamed to
HDM05's own layout), so it runs without the real data.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from mocapkit.models.motion_encoder import motion_encoder
from mocapkit.retrieval.embedding import EmbeddingRetrieval, resample_frames
from mocapkit.train.losses import contrastive_loss
from tests.shared_data import synthetic_hdm05_folder

ROOT = Path(__file__).resolve().parents[2]
TINY_MODEL = ["model.channels=[16,16]", "model.strides=[2,1]", "model.hidden=16", "model.embedding_dim=8"]
TINY = [
    *TINY_MODEL,
    "data.frames=16",
    "data.batch_size=8",
    "trainer.max_epochs=1",
    "logger=none",
    "callbacks.learning_rate=null",
    "trainer.enable_progress_bar=false",
    "data.val_fraction=0.3",
]
CLASSES = ("walk2StepsLstart", "hopBothLegs1hops")


def smooth_batch(n: int, frames: int = 32, seed: int = 0) -> torch.Tensor:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, frames)[None, :, None, None]
    x = rng.normal(0, 0.3, (n, 1, 20, 3)) + 0.1 * np.sin(t * rng.uniform(1, 3, (n, 1, 20, 3)))
    return torch.from_numpy(x.astype(np.float32))


# ------------------------------------------------------------------------------------------ encoder and losses
@pytest.mark.parametrize("trunk", ["tcn", "stgcn"])
def test_encoder_gives_unit_norm_embeddings_for_any_length(trunk):
    torch.manual_seed(0)
    model = motion_encoder(embedding_dim=12, trunk=trunk, channels=[8, 16], strides=[2, 1], hidden=16).eval()
    for frames in (16, 64, 97):
        z = model(smooth_batch(3, frames))
        assert z.shape == (3, 12)
        assert torch.allclose(z.norm(dim=1), torch.ones(3), atol=1e-5)


def test_contrastive_loss_matches_nt_xent_by_hand():
    torch.manual_seed(0)
    z = torch.nn.functional.normalize(torch.randn(6, 5), dim=1)
    labels = torch.arange(3).repeat(2)  # SimCLR: view i and i+3 are the pair
    tau = 0.1
    sim = z @ z.T / tau
    expected = []
    for i in range(6):
        j = (i + 3) % 6
        others = torch.cat([sim[i, :i], sim[i, i + 1 :]])
        expected.append(-(sim[i, j] - torch.logsumexp(others, 0)))
    assert torch.allclose(contrastive_loss(z, labels, tau), torch.stack(expected).mean(), atol=1e-5)
    assert contrastive_loss(z, torch.arange(6), tau).item() == 0.0  # no positive anywhere: zero, no NaN


@pytest.mark.parametrize("loss", ["supcon", "simclr"])
def test_both_losses_decrease_on_a_tiny_batch(loss):
    from mocapkit.retrieval.datamodule import augment
    from mocapkit.retrieval.module import MotionEmbeddingModule

    torch.manual_seed(0)
    module = MotionEmbeddingModule(
        model={
            "_target_": "mocapkit.models.motion_encoder.motion_encoder",
            "channels": [16, 16],
            "strides": [2, 1],
            "hidden": 32,
            "embedding_dim": 16,
        },
        optimizer={"_target_": "torch.optim.Adam", "_partial_": True, "lr": 3e-3},
        loss=loss,
        temperature=0.1,
    )
    base = smooth_batch(8, 40, seed=1).numpy()
    rng = np.random.default_rng(0)
    views = lambda: torch.from_numpy(np.stack([augment(s, 24, rng) for s in base]))
    labels = torch.tensor([0, 0, 1, 1, 2, 2, 3, 3])
    optimizer = module.configure_optimizers()
    fixed = {"landmarks": views(), "view2": views(), "label": labels}
    with torch.no_grad():
        before = module.loss(fixed).item()
    for _ in range(20):
        batch = {"landmarks": views(), "view2": views(), "label": labels}
        optimizer.zero_grad()
        module.loss(batch).backward()
        optimizer.step()
    with torch.no_grad():
        after = module.loss(fixed).item()
    assert after < 0.8 * before, (before, after)


# ------------------------------------------------------------------------------------------ data module
def test_resample_and_augment_keep_the_shape_and_never_mirror():
    from mocapkit.retrieval.datamodule import augment

    x = np.random.default_rng(0).normal(size=(23, 20, 3)).astype(np.float32)
    y = resample_frames(x, 64)
    assert y.shape == (64, 20, 3) and y.dtype == np.float32
    assert np.allclose(y[0], x[0]) and np.allclose(y[-1], x[-1], atol=1e-6)
    assert np.allclose(resample_frames(x, 23), x, atol=1e-6)
    assert resample_frames(x[:1], 5).shape == (5, 20, 3)
    body = np.zeros((30, 20, 3), np.float32)
    body[:, 12, 0], body[:, 16, 0] = 0.1, -0.1  # l_hip +x, r_hip -x
    for seed in range(20):
        view = augment(body, 16, np.random.default_rng(seed), jitter=0.0)
        assert view.shape == (16, 20, 3)
        assert (view[:, 12, 0] > 0).all() and (view[:, 16, 0] < 0).all()  # ±30° never swaps the sides
        assert 0.09 <= np.linalg.norm(view[0, 12]) <= 0.111  # scale 0.9-1.1


def _clips(groups=("a", "b", "c"), labels=("x", "y"), per=3):
    from mocapkit.retrieval.datamodule import Clip

    rng = np.random.default_rng(0)
    return [
        Clip(rng.normal(size=(int(rng.integers(10, 40)), 20, 3)).astype(np.float32), lab, g, f"{g}_{lab}_{i}")
        for g in groups
        for lab in labels
        for i in range(per)
    ]


def test_datamodule_holds_out_groups_and_stratifies_validation():
    from mocapkit.retrieval.datamodule import RetrievalDataModule

    dm = RetrievalDataModule(clips=_clips(), test_groups=["b"], val_fraction=0.2, frames=16, batch_size=4)
    assert dm.groups["test"] == ["b"] and dm.groups["train"] == ["a", "c"]
    assert {c.group for c in dm.test_clips} == {"b"}
    assert not {c.group for c in [*dm.train_clips, *dm.val_clips]} & {"b"}
    assert sorted(c.label for c in dm.val_clips) == ["x", "y"]  # one of each class's 6 clips
    spaces = dm.label_spaces()
    assert spaces["class_names"] == ["x", "y"]
    assert spaces["source"]["test_groups"] == ["b"] and spaces["source"]["frames"] == 16
    batch = next(iter(dm.train_dataloader()))
    assert batch["landmarks"].shape == batch["view2"].shape == (4, 16, 20, 3)
    assert not torch.equal(batch["landmarks"], batch["view2"])
    val = dm.dataset("val")
    assert int(sum(val[i]["query"] for i in range(len(val)))) == len(dm.val_clips)
    test = dm.dataset("test")
    assert len(test) == len(dm.test_clips) + len(dm.train_clips) + len(dm.val_clips)
    assert RetrievalDataModule(clips=_clips()).groups["test"] == ["a"]  # null: the first group


def _movement(family: int, length: int, phase: float) -> np.ndarray:
    """``[length, 20, 3]``: every landmark follows family ``family``'s curve (a sine of 1, 2 or 3 cycles per clip)
    started at ``phase``; clips of one family differ in length and phase, so only a warping compares them well."""
    t = np.linspace(0.0, 1.0, length)[:, None, None]
    offsets = np.linspace(0.0, 1.0, 60).reshape(1, 20, 3)
    return np.sin(2 * np.pi * (family + 1) * t + phase + offsets).astype(np.float32)


def test_dtw_neighbours_are_the_nearest_clips_by_dtw_and_never_the_clip_itself(monkeypatch):
    from mocapkit.retrieval import datamodule
    from mocapkit.retrieval.datamodule import Clip, dtw_neighbours

    rng = np.random.default_rng(0)
    families = np.repeat([0, 1, 2], 4)
    clips = [
        Clip(_movement(f, int(rng.integers(20, 50)), rng.uniform(0, 0.3)), "?", "g", str(i))
        for i, f in enumerate(families)
    ]
    neighbours = dtw_neighbours(clips, 3)
    assert neighbours.shape == (12, 3)
    assert not np.any(neighbours == np.arange(12)[:, None])
    assert np.all(families[neighbours] == families[:, None])  # the 3 other clips of its family, labels unread
    with pytest.raises(ValueError, match="data.neighbours=12"):
        dtw_neighbours(clips, 12)
    # a larger library: each clip's DTW among its nearest clips by descriptor only, the same neighbours here
    monkeypatch.setattr(datamodule, "NEIGHBOUR_CANDIDATES", 6)
    assert np.array_equal(dtw_neighbours(clips, 3), neighbours)


def test_dtw_neighbour_positives_draw_the_second_view_from_the_clip_or_its_neighbours():
    from mocapkit.retrieval.datamodule import Clip, RetrievalDataModule

    # each clip a constant value, so a view (no augmentation) says which clip it came from
    clips = [
        Clip(np.full((int(10 + 3 * i), 20, 3), float(i), np.float32), "xy"[i % 2], "ab"[i // 8], str(i))
        for i in range(16)
    ]
    still = {"crop": [1.0, 1.0], "rotation_deg": 0.0, "scale": [1.0, 1.0], "jitter": 0.0}
    dm = RetrievalDataModule(
        clips=clips, test_groups=["b"], frames=8, positives="dtw_neighbours", neighbours=2, augmentation=still
    )
    values = [float(c.landmarks[0, 0, 0]) for c in dm.train_clips]
    train = dm.dataset("train")
    assert dm.label_spaces()["source"]["positives"] == "dtw_neighbours"
    seen = set()
    for _ in range(20):
        for i in range(len(train)):
            item = train[i]
            first, second = float(item["landmarks"][0, 0, 0]), float(item["view2"][0, 0, 0])
            assert first == values[i]
            j = values.index(second)
            assert j == i or j in train.partners[i]
            seen.add(j == i)
    assert seen == {True, False}  # both the clip itself and its neighbours give second views
    with pytest.raises(ValueError, match="data.positives='labels'"):
        RetrievalDataModule(clips=clips, positives="labels")


def test_validation_clips_carry_their_dtw_neighbours_among_the_other_groups(monkeypatch):
    """With DTW-neighbour positives each validation query carries its nearest database clips by DTW (indices of
    the validation set, only other groups' clips, as val/map ranks): what val/dtw_agreement looks for."""
    from mocapkit.retrieval import datamodule
    from mocapkit.retrieval.datamodule import Clip, RetrievalDataModule, dtw_nearest

    rng = np.random.default_rng(1)
    families = np.tile([0, 1, 2], 8)  # 24 clips, 3 families, 4 groups
    clips = [
        Clip(_movement(f, int(rng.integers(20, 50)), rng.uniform(0, 0.3)), "xyz"[f], "abcd"[i % 4], str(i))
        for i, f in enumerate(families)
    ]
    dm = RetrievalDataModule(clips=clips, test_groups=["d"], frames=8, val_fraction=0.3, positives="dtw_neighbours")
    val = dm.dataset("val")
    n_queries = int(val.query.sum())
    assert n_queries >= 3
    for i in range(len(val)):
        row = val[i]["teacher"].numpy()
        if not val.query[i]:
            assert np.all(row == -1)
            continue
        assert np.all(row >= n_queries)  # database clips only
        assert np.all(val.groups[row] != val.groups[i])  # of other groups
        assert np.all(val.labels[row[:2]] == val.labels[i])  # the nearest: the query's own family (labels unread)
    same_clip = RetrievalDataModule(clips=clips, test_groups=["d"], frames=8, val_fraction=0.3)
    assert "teacher" not in same_clip.dataset("val")[0]
    # beyond NEIGHBOUR_CANDIDATES database clips the candidates come by descriptor: the same neighbours here
    queries, database = dm.val_clips, dm.train_clips
    excluded = lambda i: np.array([c.group == queries[i].group for c in database])
    exact = dtw_nearest(queries, database, 3, excluded)
    monkeypatch.setattr(datamodule, "NEIGHBOUR_CANDIDATES", 8)
    assert np.array_equal(dtw_nearest(queries, database, 3, excluded), exact)


def test_neighbour_agreement_by_hand():
    from mocapkit.retrieval.module import neighbour_agreement

    database = np.eye(4)  # clip j's embedding is axis j
    queries = np.array([[0.9, 0.1, 0.0, 0.0], [0.0, 0.0, 0.6, 0.8]])  # nearest: 0 then 1; 3 then 2
    teacher = np.array([[0, 2], [3, -1]])
    # query 0: {0, 1} holds 1 of {0, 2}; query 1: {3, 2} holds 3, its only teacher neighbour
    assert neighbour_agreement(queries, database, teacher) == pytest.approx((0.5 + 1.0) / 2)
    groups = np.array([0, 1, 0, 1])
    # with groups, query 0 (group 1) ranks only clips 0 and 2: both teacher neighbours found
    assert neighbour_agreement(queries[:1], database, teacher[:1], np.array([1]), groups) == 1.0
    assert np.isnan(neighbour_agreement(queries, database, np.full((2, 2), -1)))


@pytest.mark.parametrize("selection", ["map", "dtw_agreement"])
def test_the_selection_follows_map_or_the_dtw_agreement(selection, monkeypatch):
    """val/selection is val/map (ties by the loss) or val/dtw_agreement (ties to the later epoch); both are logged
    where the validation set carries DTW neighbours, and selecting by agreement without them is refused."""
    from mocapkit.retrieval.module import MotionEmbeddingModule
    from mocapkit.train.config import compose_config

    cfg = compose_config(["experiment=retrieval_dtw_neighbours", f"module.selection={selection}"])
    from omegaconf import OmegaConf

    module = MotionEmbeddingModule(
        **{k: v for k, v in OmegaConf.to_container(cfg.module, resolve=True).items() if not k.startswith("_")},
        class_names=["x", "y"],
    )
    logged = {}
    monkeypatch.setattr(module, "log", lambda name, value, **kw: logged.__setitem__(name, float(value)))
    z = torch.nn.functional.normalize(torch.tensor([[1.0, 0.1], [0.1, 1.0], [1.0, 0.0], [0.0, 1.0], [0.7, 0.7]]), dim=1)
    batch = {
        "z": z,
        "label": torch.tensor([0, 1, 0, 1, 1]),
        "group": torch.tensor([0, 0, 1, 1, 1]),
        "query": torch.tensor([True, True, False, False, False]),
        "teacher": torch.tensor([[2, 4], [4, 3], [-1, -1], [-1, -1], [-1, -1]]),  # validation-set indices
    }
    module._outputs["val"] = [batch]
    module._retrieval_epoch_end("val")
    # query 0's two nearest database clips: 2 then 4 (both teacher neighbours); query 1's: 3 then 4 (both)
    assert logged["val/dtw_agreement"] == 1.0
    assert logged["val/selection"] == logged[f"val/selection_by_{selection}"]
    assert logged["val/selection_by_map"] == pytest.approx(logged["val/map"] - 1e-4 * logged["val/loss"])
    del batch["teacher"]
    module._outputs["val"] = [batch]
    if selection == "map":
        module._retrieval_epoch_end("val")
    else:
        with pytest.raises(ValueError, match="data.positives=dtw_neighbours"):
            module._retrieval_epoch_end("val")


def test_retrieval_scores_by_hand():
    from mocapkit.retrieval.module import retrieval_loss, retrieval_scores

    db = np.eye(3, dtype=np.float32)
    q = np.array([[0.9, 0.1, 0.0], [0.0, 0.2, 0.8]], np.float32)
    scores = retrieval_scores(q, np.array([0, 0]), db, np.array([0, 1, 1]))
    assert scores == {"map": pytest.approx((1 + 1 / 3) / 2), "p1": 0.5, "n_queries": 2}  # 2nd query: rank 3
    # cross-group: each query only against the other groups' clips; query 0 then has no relevant clip (left out)
    scores = retrieval_scores(q, np.array([0, 0]), db, np.array([0, 1, 1]), np.array([0, 1]), np.array([0, 1, 1]))
    assert scores == {"map": 1.0, "p1": 1.0, "n_queries": 1}
    t = torch.from_numpy
    loss = retrieval_loss(t(q), t(np.array([0, 0])), t(db), t(np.array([0, 1, 1])), 0.5)
    by_hand = -np.mean([np.log(np.exp(s[0] / 0.5) / np.exp(s / 0.5).sum()) for s in q @ db.T])
    assert float(loss) == pytest.approx(by_hand, rel=1e-5)


# ------------------------------------------------------------------------------------------ train / eval / export
@pytest.fixture(scope="module")
def hdm05_folder(tmp_path_factory) -> Path:
    return synthetic_hdm05_folder(tmp_path_factory, CLASSES, clips_per_actor=3, max_frames=90)


@pytest.fixture(scope="module")
def run(hdm05_folder, tmp_path_factory) -> Path:
    from mocapkit.train.config import compose_config
    from mocapkit.train.training import train

    out = tmp_path_factory.mktemp("runs")
    cfg = compose_config(
        [
            "experiment=retrieval_supcon",
            f"data.root={hdm05_folder}",
            "data.test_groups=[mm]",
            f"output_root={out}",
            "run_name=tiny",
            *TINY,
        ]
    )
    return Path(train(cfg))


@pytest.fixture(scope="module")
def onnx_file(run) -> Path:
    from mocapkit.deploy.export import export_checkpoint

    report = export_checkpoint(run / "best.ckpt")
    assert report["max_abs_diff"] < 1e-4 and report["checked_shape"] == [3, 97, 20, 3]
    return run / "model.onnx"


@pytest.fixture(scope="module")
def motions(hdm05_folder):
    from mocapkit.datasets.mocap.folders import list_clips, read_clips

    return read_clips(list_clips("hdm05", hdm05_folder))


def test_train_records_the_split_and_eval_ranks_the_held_out_performer(run):
    from mocapkit.evaluation.evaluate import evaluate
    from mocapkit.train.checkpoints import load_checkpoint

    hp = load_checkpoint(run / "best.ckpt")["hyper_parameters"]
    assert hp["loss"] == "supcon" and hp["class_names"] == sorted(CLASSES)
    assert hp["source"]["test_groups"] == ["mm"] and hp["source"]["train_groups"] == ["bd"]
    report = evaluate(run / "best.ckpt")
    assert report["n_queries"] == 6 and 0.0 <= report["map"] <= 1.0
    assert json.loads((run / "eval" / "metrics.json").read_text())["sample_counts"]["test"] == 6


def test_export_metadata_and_dynamic_shapes(onnx_file):
    import onnxruntime as ort

    session = ort.InferenceSession(str(onnx_file), providers=["CPUExecutionProvider"])
    meta = json.loads(session.get_modelmeta().custom_metadata_map["mocapkit_embedding"])
    assert meta["frames"] == 16 and meta["fps"] == 30.0 and meta["embedding_dim"] == 8 and meta["loss"] == "supcon"
    assert len(meta["landmark_names"]) == 20 and meta["training_data"]["test_groups"] == ["mm"]
    inputs = session.get_inputs()[0]
    assert inputs.name == "landmarks" and isinstance(inputs.shape[0], str) and isinstance(inputs.shape[1], str)
    out = session.run(["embedding"], {"landmarks": smooth_batch(5, 33).numpy()})[0]
    assert out.shape == (5, 8) and np.allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-5)


# ------------------------------------------------------------------------------------------ EmbeddingRetrieval
def test_onnx_retrieval_imports_no_torch_and_matches_the_checkpoint(run, onnx_file, hdm05_folder, motions):
    script = textwrap.dedent(f"""
        import sys, json
        from mocapkit.datasets.mocap.folders import list_clips, read_clips
        from mocapkit.retrieval.embedding import EmbeddingRetrieval
        motions = read_clips(list_clips("hdm05", {str(hdm05_folder)!r}))
        method = EmbeddingRetrieval(onnx={str(onnx_file)!r}).fit(motions[:6])
        idx, dist = method.search(motions[6:], k=3)
        print(json.dumps({{"torch": sorted(m for m in sys.modules if m == "torch" or m.startswith("torch.")),
                          "idx": idx.tolist(), "sha1": method.model_sha1_}}))
    """)
    done = subprocess.run(
        [sys.executable, "-c", script],
        check=False,
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        env={"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"},
    )
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["torch"] == []
    torch_method = EmbeddingRetrieval(checkpoint=str(run / "best.ckpt")).fit(motions[:6])
    idx, _ = torch_method.search(motions[6:], k=3)
    assert idx.tolist() == result["idx"]
    assert len(result["sha1"]) == 40 and result["sha1"] != torch_method.model_sha1_


@pytest.mark.parametrize("index", ["flat", "hnsw"])
def test_faiss_search_agrees_with_brute_force_and_the_state_round_trips(onnx_file, motions, tmp_path, index):
    from mocapkit.retrieval.base import top_k

    method = EmbeddingRetrieval(onnx=str(onnx_file), index=index).fit(motions[:8])
    queries = motions[8:]
    d = method.distances(queries)
    assert d.shape == (len(queries), 8) and d.dtype == np.float64
    for k in (1, 3, 0):
        idx, dist = method.search(queries, k=k)
        ref_idx, ref_dist = top_k(d, k)
        # FAISS works in float32: unit vectors' squared distances carry ~1e-7 absolute error, so two clips within
        # that of each other are a tie either may win; the neighbours must be at the brute-force distances
        assert idx.shape == ref_idx.shape and np.allclose(dist, ref_dist, atol=1e-6)
        assert np.allclose(np.take_along_axis(d, idx, axis=1), ref_dist, atol=1e-6)
    state = method._state()
    assert all(isinstance(v, np.ndarray) and v.dtype != object for v in state.values())
    assert ("hnsw_index" in state) == (index == "hnsw")
    np.savez(tmp_path / "state.npz", **state)
    with np.load(tmp_path / "state.npz", allow_pickle=False) as saved:
        loaded = {k: saved[k] for k in saved.files}
    again = EmbeddingRetrieval(onnx=str(onnx_file), index=index)
    again._set_state(loaded)
    assert again.model_sha1_ == method.model_sha1_ and again.n_database_ == 8
    assert np.array_equal(again.search(queries, k=4)[0], method.search(queries, k=4)[0])
    assert np.allclose(again.distances(queries), d)


def test_auto_index_is_flat_for_small_libraries_and_hnsw_for_large_ones(onnx_file, motions, monkeypatch):
    from mocapkit.retrieval import ann

    small = EmbeddingRetrieval(onnx=str(onnx_file)).fit(motions[:8])
    assert small.index == "auto" and small.index_kind_ == "flat" and "hnsw_index" not in small._state()
    monkeypatch.setattr(ann, "AUTO_HNSW_MIN_CLIPS", 8)
    large = EmbeddingRetrieval(onnx=str(onnx_file)).fit(motions[:8])
    assert large.index_kind_ == "hnsw" and "hnsw_index" in large._state()
    assert np.array_equal(large.search(motions[8:], k=3)[0], small.search(motions[8:], k=3)[0])
    again = EmbeddingRetrieval(onnx=str(onnx_file))
    again._set_state(large._state())
    assert again.index_kind_ == "hnsw"
    monkeypatch.setattr(ann, "AUTO_HNSW_MIN_CLIPS", 9)
    again._set_state(large._state())
    assert again.index_kind_ == "hnsw"  # a saved HNSW graph is used as it was built


def test_an_index_refuses_another_model(onnx_file, motions, tmp_path):
    method = EmbeddingRetrieval(onnx=str(onnx_file)).fit(motions[:4])
    state = method._state()
    other = tmp_path / "other.onnx"
    other.write_bytes(onnx_file.read_bytes() + b"\0")  # another file: another digest
    with pytest.raises(ValueError, match="SHA-1"):
        EmbeddingRetrieval(onnx=str(other))._set_state(state)


def test_a_list_of_runs_picks_the_one_that_held_out_the_absent_groups(run, motions, tmp_path):
    ckpt = torch.load(run / "best.ckpt", map_location="cpu", weights_only=True)
    ckpt["hyper_parameters"]["source"] = {
        **ckpt["hyper_parameters"]["source"],
        "test_groups": ["bd"],
        "train_groups": ["mm"],
    }
    other = tmp_path / "fold_bd.ckpt"
    torch.save(ckpt, other)
    runs = [str(other), str(run / "best.ckpt")]
    bd = [m for m in motions if m.metadata["group"] == "bd"]
    mm = [m for m in motions if m.metadata["group"] == "mm"]
    assert EmbeddingRetrieval(checkpoint=runs).fit(bd).checkpoint_used_ == str(run / "best.ckpt")  # mm absent
    assert EmbeddingRetrieval(checkpoint=runs).fit(mm).checkpoint_used_ == str(other)
    with pytest.raises(ValueError, match="held out exactly"):
        EmbeddingRetrieval(checkpoint=runs).fit(motions)


def test_a_users_folder_trains_a_self_supervised_embedding_that_indexes_it(hdm05_folder, tmp_path, capsys):
    """A library without labels: every motion file under a folder trains the DTW-neighbour embedding
    (``data.dataset=folder``, nothing held out), which is exported and indexes that folder through the CLI."""
    from mocapkit.cli import main as cli
    from mocapkit.deploy.export import export_checkpoint
    from mocapkit.retrieval.datamodule import RetrievalDataModule
    from mocapkit.retrieval.index import RetrievalIndexError, make_method
    from mocapkit.train.checkpoints import load_checkpoint
    from mocapkit.train.config import compose_config
    from mocapkit.train.training import train

    dm = RetrievalDataModule(dataset="folder", root=str(hdm05_folder))
    assert dm.groups == {"train": ["library"], "test": [], "all": ["library"]} and not dm.test_clips
    assert {c.label for c in dm.train_clips} == {"bd", "mm"}  # the sub-folders
    flat = tmp_path / "flat"  # the same files in one folder: no label at all
    flat.mkdir()
    for path in hdm05_folder.rglob("*.*"):
        shutil.copy(path, flat / path.name)
    cfg = compose_config(
        [
            "experiment=retrieval_dtw_neighbours",
            "data.dataset=folder",
            f"data.root={flat}",
            "data.neighbours=2",
            f"output_root={tmp_path}",
            "run_name=library",
            *TINY,
            "trainer.max_epochs=2",
        ]
    )
    run = Path(train(cfg))
    best = load_checkpoint(run / "best.ckpt")
    source = best["hyper_parameters"]["source"]
    assert source["dataset"] == "folder" and source["positives"] == "dtw_neighbours" and source["neighbours"] == 2
    assert best["epoch"] == load_checkpoint(run / "last.ckpt")["epoch"] == 1  # one label: nothing to select by
    export_checkpoint(run / "best.ckpt")
    index = tmp_path / "library.index"
    args = ["index", "--src", str(hdm05_folder), "--out", str(index), "--method", "embedding"]
    assert cli([*args, "--ckpt", str(run / "model.onnx")]) == 0
    query = min((hdm05_folder / "bd").glob("*.amc"))
    capsys.readouterr()
    assert cli(["search", "--index", str(index), str(query), "-k", "3", "--json"]) == 0
    hits = json.loads(capsys.readouterr().out)[0]["results"]
    assert len(hits) == 3 and str(query.resolve()) not in {h["path"] for h in hits}
    with pytest.raises(RetrievalIndexError, match="--ckpt is for --method embedding; dtw_positions"):
        make_method("dtw_positions", ckpt=run / "model.onnx")
    with pytest.raises(ValueError, match="no motion file"):
        RetrievalDataModule(dataset="folder", root=str(tmp_path / "library.index"))
